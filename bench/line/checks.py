"""Checks of a sequence against a station and its limits, before a unit is scanned (the line's
commands and the operator station share them)."""

from __future__ import annotations

from typing import Any

from . import LineError


def check_limits_measured(seq: Any, limits: Any) -> None:
    """Every limit names a measurement some step of the sequence measures (else the unit could only
    end in ERROR): refused before a unit is scanned."""
    from procedures import find_procedure

    measured = {(m.name, step.procedure) for step in seq.steps for m in find_procedure(step.procedure).measurements}
    for lim in limits.limits:
        if not any(name == lim.name and lim.procedure in (None, proc) for name, proc in measured):
            raise LineError(f"{limits.source}: [limits.{lim.name}] names a measurement no step of sequence "
                            f"{seq.name!r} measures (its steps: {', '.join(s.procedure for s in seq.steps)})")


def check_steps(seq: Any, station: Any) -> None:
    """Every step's procedure fits the station (its device roles, the kind of gyro, the limits),
    before a unit is scanned; LineError names the step and why."""
    from bench.engine.demands import StationMismatch, check_station

    if getattr(seq, "write_trims", False) and "fpga" not in station.config.devices:
        raise LineError(f"{seq.source}: [trims] write = true needs an FPGA to hold the trims; station "
                        f"{station.id!r} has {sorted(station.config.devices)}")
    for i, step in enumerate(seq.steps, 1):
        proc = step.make()
        missing = [r for r in proc.requires if r not in station.config.devices]
        if missing:
            raise LineError(f"{seq.source}: [[step]] #{i} {step.procedure} needs device role(s) {missing}; "
                            f"station {station.id!r} has {sorted(station.config.devices)}")
        try:
            check_station(proc, station)
        except StationMismatch as exc:
            raise LineError(f"{seq.source}: [[step]] #{i} {step.procedure}: {exc}") from None
