"""The station entry of any PyMeasure instrument (`driver = "pymeasure"` under `[devices.<name>]`,
any name but table/frontend/fpga): its keys, how to build it, its health and safe state."""

from __future__ import annotations

import importlib
from typing import Any

from bench.devices import DriverSpec, Key, StationError, register_driver
from bench.streams import Column, StreamSchema, declare


def _build(cfg: dict[str, Any], clock: Any) -> Any:
    from .station_device import InstrumentDevice, column_name

    role = cfg["role"]
    if not cfg["resource"]:
        raise StationError(f"[devices.{role}] resource: the instrument's VISA resource is missing")
    record = cfg["record"]
    if record:  # the columns each link check logs, with their units, under the device's role
        columns = (Column("t_s", "s"), *(Column(column_name(p), u) for p, u in record.items()))
        declare(StreamSchema(role, f"instrument {cfg['class']}", columns))
    dev = InstrumentDevice(
        role,
        cfg["class"],
        cfg["resource"],
        setup=cfg["setup"],
        safe=cfg["safe"],
        record=record,
        timeout_s=cfg["timeout_s"],
    )
    try:
        dev.connect()
    except Exception:
        dev.close()
        raise
    return dev


def _check(where: str, cfg: dict[str, Any]) -> None:
    """`record` maps property paths to unit text; `class` names a module and a class."""
    from .station_device import column_name

    for path, unit in cfg["record"].items():
        if not isinstance(unit, str) or not column_name(path).isidentifier():
            raise StationError(f"{where} record: {path} = {unit!r} must be a property path = its unit (text)")
    for table in ("setup", "safe"):
        for path in cfg[table]:
            if not column_name(path).isidentifier():
                raise StationError(f"{where} {table}: {path!r} is not a property path (ch_1.output_enabled)")
    if "." not in cfg["class"]:
        raise StationError(f"{where} class = {cfg['class']!r} must be module.Class (pymeasure.instruments...)")


def _health(dev: Any, since: Any = None) -> Any:
    return dev.health()


def _serve(world: Any, cfg: dict[str, Any]) -> tuple[Any, dict[str, Any]]:
    """On a simulated station: the `simulator = "module:function"` the station file names."""
    role, target = cfg.get("role", "?"), cfg.get("simulator") or ""
    module, _, func = target.partition(":")
    if not module or not func:
        raise StationError(
            f'[devices.{role}] simulator: a simulated station needs simulator = "module:function" '
            f"for a PyMeasure instrument (got {target!r})"
        )
    try:
        serve = getattr(importlib.import_module(module), func)
    except (ImportError, AttributeError) as exc:
        raise StationError(f"[devices.{role}] simulator = {target!r} cannot be loaded ({exc})") from None
    return serve(world, cfg)


SPEC = register_driver(
    DriverSpec(
        name="pymeasure",
        role="instrument",
        part="outputs-off",
        keys={
            "driver": Key(str, required=True),
            "class": Key(str, required=True, doc="the PyMeasure class (pymeasure.instruments.keithley.Keithley2200)"),
            "resource": Key(str, "", doc="VISA resource (TCPIP::host::port::SOCKET, GPIB0::12::INSTR, ASRL...)"),
            "timeout_s": Key(float, 2.0, 0.05, 60.0, doc="deadline of one query", unit="s"),
            "setup": Key(dict, {}, doc="property = value set (and read back) at connect"),
            "safe": Key(dict, {}, doc="property = value set and read back at the safe state"),
            "record": Key(dict, {}, doc="property = unit, logged into every run at each link check"),
            "simulator": Key(str, "", doc="module:function serving its simulator (simulated stations)"),
        },
        build=_build,
        serve=_serve,
        health=_health,
        check_config=_check,
        doc="any PyMeasure instrument: set up at connect, logged at each link check, safe values at the safe state",
    )
)
