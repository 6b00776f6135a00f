"""FPGA register link: protocol (frame codec, register map), the stream's layout and the FpgaLink
driver.  Imported on first use (PEP 562): a report reads `drivers.fpga.stream` without the link's
compiled frame kernels (numba)."""

from __future__ import annotations

from typing import Any

__all__ = ["FpgaLink", "LinkStats", "STREAM_COLUMNS"]


def __getattr__(name: str) -> Any:
    if name in ("FpgaLink", "LinkStats"):
        from . import link

        return getattr(link, name)
    if name == "STREAM_COLUMNS":
        from .stream import STREAM_COLUMNS

        return STREAM_COLUMNS
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
