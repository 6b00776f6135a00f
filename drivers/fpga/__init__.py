"""FPGA register link: protocol (frame codec, register map) and the FpgaLink driver."""

from .link import FpgaLink, LinkStats
from .protocol import STREAM_COLUMNS

__all__ = ["FpgaLink", "LinkStats", "STREAM_COLUMNS"]
