"""What a procedure will ask of each device, and whether the station may be asked that.

A procedure declares, from its parameters, the largest rate, acceleration or amplitude it will
command (`Procedure.demands()`), and which kinds of gyro it is written for (`kinds`).  The engine
checks both against the station before the first step, so a run that would fail on a limit or
on the wrong gyro is refused before anything moves, not half-way through.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

#: kinds of gyro a station can hold (the station file's `[station] kind`)
KINDS: tuple[str, ...] = ("hrg", "mems-ring")


@dataclass(frozen=True)
class Demand:
    """One value a procedure will command: the device role, the station key that limits it
    (`max_rate_dps`), the quantity with its unit, and the value (its magnitude is checked)."""

    role: str
    limit_key: str
    quantity: str
    value: float
    unit: str = ""

    def text(self) -> str:
        unit = f" {self.unit}" if self.unit else ""
        return f"{self.quantity}={self.value:g}{unit}"


class StationMismatch(ValueError):
    """The procedure asks more of the station than its limits allow, or is for another kind of
    gyro.  The message names the value and the limit (or the kinds)."""


def check_demands(demands: Iterable[Demand], station: Any, procedure: str = "") -> None:
    """Raise StationMismatch for the first demand above the station's limit (`station.limit`;
    a station object without limits is not checked)."""
    lookup = getattr(station, "limit", None)
    if lookup is None:
        return
    for d in demands:
        limit = lookup(d.role, d.limit_key)
        if limit is None:
            continue
        if not abs(float(d.value)) <= float(limit):
            unit = f" {d.unit}" if d.unit else ""
            who = f"{procedure}: " if procedure else ""
            raise StationMismatch(
                f"{who}{d.text()} is above the station's limit {float(limit):g}{unit} "
                f"({getattr(station, 'id', 'station')}: [devices.{d.role}] {d.limit_key} = {float(limit):g}); "
                "nothing was moved"
            )


def kind_refusal(kinds: Iterable[str], station_kind: str) -> str | None:
    """Why a procedure for `kinds` must not run on a station holding `station_kind` (None: it may).
    A procedure with no kinds runs on any station; a station of unknown kind ("") takes any."""
    kinds = tuple(kinds)
    if not kinds or not station_kind or station_kind in kinds:
        return None
    return f"it is for {', '.join(kinds)} gyros and the station's gyro is {station_kind} ([station] kind)"


def check_station(proc: Any, station: Any) -> None:
    """The pre-run check of a procedure (instance) against a station (opened or not): kind, then
    limits; StationMismatch before anything moves."""
    why = kind_refusal(getattr(proc, "kinds", ()), getattr(station, "kind", ""))
    if why is not None:
        raise StationMismatch(f"procedure {proc.name!r} cannot run on station {getattr(station, 'id', '?')!r}: {why}")
    check_demands(proc.demands(), station, proc.name)
    preflight = getattr(proc, "preflight", None)
    devices = getattr(station, "devices", None)
    if preflight is not None and devices:  # an opened station: the devices' own limits (read only)
        try:
            preflight(devices)
        except StationMismatch:
            raise
        except Exception:  # noqa: BLE001, S110 - a device that cannot answer now: the run's steps meet it
            pass
