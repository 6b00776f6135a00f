"""A station file (TOML) read and checked: its [station], [simulation] and [devices.<role>] tables,
each value checked by bench.validation through `Key.check` against the keys its driver's spec declares."""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from bench.devices import DRIVERS, INSTRUMENT, ROLES, Key, StationError, check_table
from bench.validation import missing_key, not_a, not_one_of

BUILTIN_DIR = Path(__file__).resolve().parent / "stations"

STATION_KEYS = {
    "id": Key(str, required=True, doc="the station's name in runs and results"),
    "results": Key(str, "runs/results.sqlite", doc="SQLite file or database URL"),
    "runs_dir": Key(str, "runs", doc="folder of the raw files"),
    "description": Key(str, "", doc="one line for people"),
    "kind": Key(str, "", choices=("", "hrg", "mems-ring"), doc="gyro held: hrg, mems-ring ('' = not said)"),
    # where the sensitive axis points, for Earth's rate on it (docs/noise_model.md)
    "latitude_deg": Key(float, 0.0, -90.0, 90.0, doc="the station's latitude (north > 0)", unit="deg"),
    "axis_elevation_deg": Key(float, 90.0, -90.0, 90.0, doc="sensitive axis above the horizontal (90 = up)",
                              unit="deg"),
    "axis_azimuth_deg": Key(float, 0.0, 0.0, 360.0, doc="sensitive axis from north toward east", unit="deg"),
}
#: the kind of gyro a simulated station holds when its file does not say
PRESET_KINDS = {"hrg": "hrg", "hrg-wa": "hrg", "hrg-selfcal": "hrg", "mems": "mems-ring"}
SIM_KEYS = {
    "preset": Key(str, "hrg", choices=("hrg", "hrg-wa", "hrg-selfcal", "mems"),
                  doc="simulated resonator (and its noise)"),
    "seed": Key(int, 0, 0, 2**63 - 1, doc="random seed of the simulation"),
    "speed": Key(float, 0.0, 0.0, 1e6, doc="0 = lockstep, else x real time"),
    "sample_period_s": Key(float, 1e-3, 1e-5, 0.1, doc="simulated sample period", unit="s"),
    "earth_rate": Key(bool, False, doc="simulate Earth's rate on the axis ([station] latitude and axis)"),
}


@dataclass
class StationConfig:
    """A checked station file."""

    source: str
    station: dict[str, Any]
    simulation: dict[str, Any] | None
    devices: dict[str, dict[str, Any]] = field(default_factory=dict)

    @property
    def id(self) -> str:
        return self.station["id"]


def builtin_stations() -> dict[str, Path]:
    return {p.stem: p for p in sorted(BUILTIN_DIR.glob("*.toml"))}


def find_station_file(name_or_path: str | Path) -> Path:
    """A built-in station name (`sim-hrg`) or a TOML file path."""
    text = str(name_or_path)
    builtin = builtin_stations()
    if text in builtin:
        return builtin[text]
    path = Path(text)
    if path.is_file():
        return path
    raise StationError(f"{text}: no such station file or built-in station (built-in: {', '.join(builtin)})")


def load_config(name_or_path: str | Path) -> StationConfig:
    """Read and check a station file; StationError names the file, key, value and range."""
    path = find_station_file(name_or_path)
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise StationError(f"{path}: not valid TOML: {exc}") from None
    except UnicodeDecodeError as exc:
        raise StationError(
            f"{path}: not UTF-8 text (byte 0x{exc.object[exc.start]:02x} at offset {exc.start}); save it as UTF-8"
        ) from None
    except OSError as exc:
        raise StationError(f"{path}: cannot be read: {exc.strerror or exc}") from None
    for top in raw:
        if top not in ("station", "simulation", "devices"):
            raise StationError(f"{path}: unknown table [{top}] (allowed: station, simulation, devices)")
    if "station" not in raw:
        raise StationError(f'{path}: missing table [station] with id = "..."')
    for top in ("station", "simulation", "devices"):
        if top in raw and not isinstance(raw[top], dict):
            raise StationError(f"{path}: {not_a(top, raw[top], 'a table ([' + top + '])')}")
    station = check_table(f"{path}: [station]", raw["station"], STATION_KEYS)
    sim = check_table(f"{path}: [simulation]", raw["simulation"], SIM_KEYS) if "simulation" in raw else None
    devices: dict[str, dict[str, Any]] = {}
    for role, table in (raw.get("devices") or {}).items():
        where = f"{path}: [devices.{role}]"
        if role not in ROLES and not role.isidentifier():
            raise StationError(
                f"{path}: [devices.{role}] {role!r} is not a name (roles: {', '.join(ROLES)}, or a name of your "
                f"own, letters, digits and _, for an instrument)"
            )
        if not isinstance(table, dict):
            raise StationError(f"{path}: {not_a(f'devices.{role}', table, 'a table')}")
        name = table.get("driver")
        kind = role if role in ROLES else INSTRUMENT
        fitting = sorted(n for n, spec in DRIVERS.items() if spec.role == kind)
        if name is None:
            raise StationError(f"{where} {missing_key('driver', 'one of ' + ', '.join(fitting))}")
        if not isinstance(name, str) or name not in DRIVERS:
            raise StationError(f"{where} {not_one_of('driver', name, fitting)}")
        spec = DRIVERS[name]
        if kind == INSTRUMENT and spec.role in ROLES:
            raise StationError(
                f"{where} unknown role {role!r}: a {spec.role} driver goes under [devices.{spec.role}] "
                f"(a name of your own holds an instrument: driver = one of {', '.join(fitting)})"
            )
        if spec.role != kind:
            raise StationError(f"{where} {not_one_of('driver', name, fitting)} (it is a {spec.role} driver)")
        cfg = check_table(where, table, spec.keys)
        if spec.check_config is not None:
            spec.check_config(where, cfg)
        if kind == INSTRUMENT:
            cfg["role"] = role  # the instrument's name in the run, its logged stream and `ctx.devices`
        if sim is None:
            missing = [k for k in ("resource", "url") if k in spec.keys and not cfg.get(k)]
            if missing:
                raise StationError(f"{where} {missing_key(missing[0], 'a real device needs its address')}")
        devices[role] = cfg
    if not devices:
        raise StationError(f"{path}: no [devices.*] table (roles: {', '.join(ROLES)})")
    return StationConfig(source=str(path), station=station, simulation=sim, devices=devices)
