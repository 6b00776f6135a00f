"""Errors every driver raises, so the engine can tell a bad value from a lost link."""

from __future__ import annotations

from bench.validation import LimitError  # the shared wording of a bad value (bench.validation)

__all__ = ["DeviceError", "LimitError", "LinkLostError", "ProtocolError", "SafetyTripError"]


class DeviceError(RuntimeError):
    """The device reported an error (exception response, error queue entry, NACK, fault bit)."""


class LinkLostError(ConnectionError):
    """The device stopped answering within its (wall-clock) timeout, or the link dropped."""


class ProtocolError(DeviceError):
    """A reply was short, malformed or failed its checksum."""


class SafetyTripError(DeviceError):
    """The device stopped itself: e-stop, interlock open, watchdog expired or a drive fault."""
