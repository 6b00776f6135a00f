"""Rate-table drivers: the interface procedures use, and one driver per controller model.

Imported on first use (PEP 562): a simulator that takes only a protocol module, or a station with
another table, does not import pymodbus or pyserial with the drivers it does not build (issue 36)."""

from __future__ import annotations

import importlib
from typing import Any

#: each name and the module of this package that defines it
_WHERE = {
    "AsciiRateTable": "ascii_driver",
    "ModbusRateTable": "modbus_driver",
    "RateTable": "base",
    "TableLimits": "base",
    "TableStatus": "base",
    "angle_error_deg": "base",
}

__all__ = ["AsciiRateTable", "ModbusRateTable", "RateTable", "TableLimits", "TableStatus", "angle_error_deg"]


def __getattr__(name: str) -> Any:
    if name in _WHERE:
        return getattr(importlib.import_module(f"{__name__}.{_WHERE[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
