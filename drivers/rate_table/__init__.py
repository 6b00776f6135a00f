"""Rate-table drivers: the interface procedures use, and one driver per controller model."""

from .ascii_driver import AsciiRateTable
from .base import RateTable, TableLimits, TableStatus, angle_error_deg
from .modbus_driver import ModbusRateTable

__all__ = ["AsciiRateTable", "ModbusRateTable", "RateTable", "TableLimits", "TableStatus", "angle_error_deg"]
