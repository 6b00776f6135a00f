"""The composition root: a station file becomes a station here, and only here does the engine's
station meet the simulators.  A real station is a `bench.station.Station` (or, with `[slots.N]`
tables, a `bench.slots.BatchStation`) of real drivers; a station file with a `[simulation]` table
becomes a `SimStation` / `SimBatchStation` (bench.composition.sim_station, .sim_batch_station): a
simulated World on virtual time, each device's simulator served on loopback and the same real
drivers pointed at it.  Callers ask `load_station(name_or_path)` and never name the kind.
docs/architecture.md gives the layer order this keeps."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from bench.devices import StationError
from bench.slots import BatchStation
from bench.station import Station
from bench.station_config import StationConfig, load_config


def warm_simulators(on_compile: Any = None) -> None:
    """Load (on a cold cache: compile) the simulated devices' kernels now, naming each as it
    compiles to `on_compile(name)` (simulators/warm.py says why this comes before a station serves)."""
    from simulators.warm import warm_kernels

    warm_kernels(on_compile=on_compile)


def _refuse_overrides(config: StationConfig, overrides: dict[str, Any]) -> None:
    """--seed, --speed and the like apply only to a simulated station: name them."""
    if overrides:
        options = ", ".join(f"--{k}" for k in sorted(overrides))
        verb = "applies" if len(overrides) == 1 else "apply"
        raise StationError(f"{config.source}: a real station; {options} {verb} only to a simulated one")


def load_station(name_or_path: str | Path, *, unit: dict[str, float] | None = None,
                 **overrides: Any) -> Station | BatchStation:
    """Check a station file and build its (unopened) station: real or simulated, one gyro or
    several on one table (slots).  `overrides` (seed, speed, preset ...) apply to a simulated one;
    `unit` changes the simulated unit's true parameters from its preset's (a campaign's grids and
    draws: {"tau_s": 320.0, ...}), as `simulated_unit` builds them."""
    config = load_config(name_or_path)
    if unit:
        if config.simulation is None or config.slots:
            raise StationError(
                f"{config.source}: the unit's true parameters apply only to a simulated one-gyro station")
        preset_name = overrides.get("preset") or config.simulation["preset"]
        overrides["resonator"] = simulated_unit(preset_name, **unit)
    if config.slots:
        return load_batch_station(config, **overrides)
    if config.simulation is not None:
        from .sim_station import SimStation

        return SimStation(config, **overrides)
    _refuse_overrides(config, overrides)
    return Station(config)


def simulated_unit(preset: str, **changes: float) -> Any:
    """The resonator parameters of a simulated preset ("hrg", "mems" ...), with `changes` to some of
    them: what `gyrobench design` takes its defaults from and what a campaign varies.  ValueError
    (simulators.physics.params.ParameterError) naming the known presets or parameters when one is not."""
    from simulators.physics.params import preset as make_preset

    return make_preset(preset, **changes)


def load_batch_station(name_or_path: str | Path | StationConfig, **overrides: Any) -> BatchStation:
    """A several-gyros station (one table, N slots) from its station file, real or simulated."""
    config = name_or_path if isinstance(name_or_path, StationConfig) else load_config(name_or_path)
    if config.simulation is not None:
        from .sim_batch_station import SimBatchStation

        return SimBatchStation(config, **overrides)
    _refuse_overrides(config, overrides)
    return BatchStation(config)
