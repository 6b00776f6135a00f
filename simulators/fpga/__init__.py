"""The simulated FPGA: firmware loops on the World and its link server."""

from .firmware import FpgaFirmware
from .server import FpgaServer, serve_fpga

__all__ = ["FpgaFirmware", "FpgaServer", "serve_fpga"]
