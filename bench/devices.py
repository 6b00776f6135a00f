"""The device registry: each instrument model declares a `DriverSpec` next to its driver
(`drivers/<kind>/<model>_spec.py` or `drivers/<kind>/spec.py`) and registers it here.

A spec says everything the station needs to know about one model: its config keys, how to build
the driver, how to ask it for a sign of life, its safe-state step and which part of the engine's
safe state it plays (`bench.devices.SAFE_PARTS`), its stream (if any) and where its
simulator is served.  The station never names a model or a role: a new rate-table model is one
new `drivers/rate_table/<model>_spec.py` (+ its simulator), found by `load_builtin_drivers`.
"""

from __future__ import annotations

import importlib
import pkgutil
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from bench.validation import KIND_WORDS, ValidationError, convert, missing_key, unknown_name

#: the parts of a station's safe state, in the order they are done; each device's spec says which
#: part it plays.  A part holds a list of devices, so with several gyros on one table every slot's
#: drive is cut before the one shared table is brought to rest, and then every slot's outputs go off
SAFE_PARTS: tuple[str, ...] = ("drive-cut", "table-to-rest", "chamber-to-ambient", "outputs-off")
#: the roles a station file may name (`[devices.<role>]`; `chamber`: a temperature chamber,
#: docs/chamber.md); the several-gyros issue adds slots of
#: `frontend`/`fpga` (N front ends and N links per station) beside the one shared `table`
ROLES = ("table", "frontend", "fpga", "chamber")
#: the role of a driver placed under any other name (`[devices.dmm]`, `[devices.supply]`): an
#: instrument the station sets up, logs and makes safe, and procedures reach as `ctx.devices.<name>`
INSTRUMENT = "instrument"


class StationError(ValueError):
    """A station file is missing, malformed or has a value outside its allowed range; the message
    names the file, the key, the value and the range."""


# --- config keys ---------------------------------------------------------------------------
@dataclass(frozen=True)
class Key:
    """One allowed key of a device table: its type, range (inclusive), unit and default."""

    type: type
    default: Any = None
    low: float | None = None
    high: float | None = None
    required: bool = False
    doc: str = ""
    choices: tuple[Any, ...] | None = None
    unit: str = ""

    def range_text(self) -> str:
        if self.choices is not None:
            return "one of " + ", ".join(repr(c) for c in self.choices)
        if self.type in (int, float):
            lo = "-inf" if self.low is None else f"{self.low:g}"
            hi = "inf" if self.high is None else f"{self.high:g}"
            return f"[{lo}, {hi}]"
        return KIND_WORDS.get(self.type, f"a {self.type.__name__}")

    def check(self, where: str, name: str, value: Any) -> Any:
        """The value, checked; StationError `<where> <name>=<value> is ...` (bench.validation)."""
        try:
            return convert(name, value, self.type, low=self.low, high=self.high, unit=self.unit, choices=self.choices)
        except ValidationError as exc:
            raise StationError(f"{where} {exc}".strip()) from None


def check_table(where: str, table: Any, keys: dict[str, Key]) -> dict[str, Any]:
    """Check every key of a TOML table against its Key; defaults filled in."""
    if not isinstance(table, dict):
        raise StationError(f"{where} is {table!r}, not a table")
    out: dict[str, Any] = {}
    for name in table:
        if name not in keys:
            raise StationError(f"{where} {unknown_name(name, 'unknown key', keys)}")
    for name, key in keys.items():
        if name in table:
            out[name] = key.check(where, name, table[name])
        elif key.required:
            raise StationError(f"{where} {missing_key(name, key.range_text())}")
        else:
            out[name] = key.default
    return out


# --- specs ---------------------------------------------------------------------------------
def close_devices(devices: dict[str, Any], roles: list[str] | None = None) -> None:
    """Close the drivers of `roles` (default: all) in the reverse of their order, each whatever the
    others do (closing must go on), then forget all of them."""
    for role in reversed(list(devices) if roles is None else roles):
        dev = devices.get(role)
        if dev is not None:
            try:
                dev.close()
            except Exception:  # noqa: BLE001 - closing must go on
                pass
    devices.clear()


def _device_safe_state(device: Any) -> bool:
    return bool(device.safe_state())


@dataclass(frozen=True)
class StreamSpec:
    """A device's continuous stream: its columns, how to start and stop it, and the counters
    (lost/corrupt/unconsumed blocks) whose values at the start of a run the health check compares
    against.  start(device, cfg); stop(device, clock); counters(device) -> tuple."""

    columns: tuple[str, ...]
    start: Callable[[Any, dict[str, Any]], None]
    stop: Callable[[Any, Any], None]
    counters: Callable[[Any], Any] | None = None


@dataclass(frozen=True)
class DriverSpec:
    """How to build one instrument model's driver, check it, make it safe and simulate it.

    build(cfg, clock) -> connected driver.  health(device, since) -> optional (n, k) rows (columns
    `health_columns`) for the role's stream, raising LinkLostError / SafetyTripError when the
    device is gone or tripped; `since` is `stream.counters(device)` taken when this run's stream
    started (None before).  part: which part of the engine's safe state this device plays (one of
    SAFE_PARTS); safe_state(device) -> True when confirmed by read-back.  serve(world, cfg) ->
    (simulator handle, address keys for the driver), or "module:function" imported when a
    simulated station starts (so drivers never import simulators)."""

    name: str
    role: str
    keys: dict[str, Key]
    build: Callable[[dict[str, Any], Any], Any]
    serve: Callable[[Any, dict[str, Any]], tuple[Any, dict[str, Any]]] | str | None = None
    health: Callable[..., Any] | None = None
    doc: str = ""
    part: str = ""
    safe_state: Callable[[Any], bool] = _device_safe_state
    health_columns: tuple[str, ...] = ()
    stream: StreamSpec | None = None
    #: check_config(where, cfg) -> None: what a key's type cannot say (StationError names the key)
    check_config: Callable[[str, dict[str, Any]], None] | None = None

    def serve_simulator(self, world: Any, cfg: dict[str, Any]) -> tuple[Any, dict[str, Any]]:
        """Start this model's simulator on the world; (handle, address keys)."""
        serve = self.serve
        if isinstance(serve, str):
            module, _, func = serve.partition(":")
            serve = getattr(importlib.import_module(module), func)
        if serve is None:
            raise StationError(f"driver {self.name!r} has no simulator")
        return serve(world, cfg)


DRIVERS: dict[str, DriverSpec] = {}


def register_driver(spec: DriverSpec) -> DriverSpec:
    """Add a model to the registry (the name in a station file's `driver = ...`)."""
    if spec.role not in (*ROLES, INSTRUMENT):
        raise ValueError(f"driver {spec.name!r}: role {spec.role!r} is not one of {(*ROLES, INSTRUMENT)}")
    if spec.part not in SAFE_PARTS:
        raise ValueError(f"driver {spec.name!r}: part {spec.part!r} is not one of {SAFE_PARTS} (its safe-state part)")
    DRIVERS[spec.name] = spec
    return spec


def unregister_driver(name: str) -> None:
    """Remove a model (tests that register a toy one)."""
    DRIVERS.pop(name, None)


def load_builtin_drivers() -> None:
    """Import every `drivers/<kind>/spec.py` and `drivers/<kind>/*_spec.py`: each registers itself."""
    # found by name, like entry points: the registry (a data contract) imports no driver module
    drivers = importlib.import_module("drivers")
    for kind in sorted(pkgutil.iter_modules(drivers.__path__), key=lambda m: m.name):
        if not kind.ispkg:
            continue
        package = importlib.import_module(f"drivers.{kind.name}")
        for mod in sorted(pkgutil.iter_modules(package.__path__), key=lambda m: m.name):
            if mod.name == "spec" or mod.name.endswith("_spec"):
                importlib.import_module(f"drivers.{kind.name}.{mod.name}")


load_builtin_drivers()
