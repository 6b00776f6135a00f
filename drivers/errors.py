"""Errors every driver raises, so the engine can tell a bad value from a lost link."""

from __future__ import annotations


class DeviceError(RuntimeError):
    """The device reported an error (exception response, error queue entry, NACK, fault bit)."""


class LimitError(ValueError):
    """A requested value is outside a configured or device limit; raised before anything is
    written.  The message names the value and the limit."""

    def __init__(self, name: str, value: float, limit: str | float, unit: str = "") -> None:
        self.name, self.value, self.limit, self.unit = name, value, limit, unit
        u = f" {unit}" if unit else ""
        super().__init__(f"{name}={value!r}{u} is outside the limit {limit}{u}")


class LinkLostError(ConnectionError):
    """The device stopped answering within its (wall-clock) timeout, or the link dropped."""


class ProtocolError(DeviceError):
    """A reply was short, malformed or failed its checksum."""


class SafetyTripError(DeviceError):
    """The device stopped itself: e-stop, interlock open, watchdog expired or a drive fault."""
