"""The DAC/ADC front end: SCPI command vocabulary, property layer and driver.

The driver is imported on first use (PEP 562): the simulated front end takes only the command
vocabulary, and a process that builds no SCPI front end does not import pyvisa (issue 36)."""

from __future__ import annotations

from typing import Any

__all__ = ["FrontEndChannel", "FrontEndLimits", "ScpiFrontEnd"]


def __getattr__(name: str) -> Any:
    if name in __all__:
        from . import driver

        return getattr(driver, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
