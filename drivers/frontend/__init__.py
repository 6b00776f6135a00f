"""The DAC/ADC front end: SCPI command vocabulary, property layer and driver."""

from .driver import FrontEndChannel, FrontEndLimits, ScpiFrontEnd

__all__ = ["FrontEndChannel", "FrontEndLimits", "ScpiFrontEnd"]
