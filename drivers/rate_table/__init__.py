"""Rate-table drivers: the interface procedures use, and one driver per controller model."""

from .base import RateTable, TableLimits, TableStatus

__all__ = ["RateTable", "TableLimits", "TableStatus"]
