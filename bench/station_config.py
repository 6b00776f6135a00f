"""A station file (TOML) read and checked: its [station], [simulation] and [devices.<role>] tables,
each value checked by bench.validation through `Key.check` against the keys its driver's spec declares."""

from __future__ import annotations

import datetime
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from bench.devices import DRIVERS, INSTRUMENT, ROLES, Key, StationError, check_table
from bench.nominal import NOMINAL_KEYS
from bench.validation import ValidationError, check_label, missing_key, not_a, not_one_of, unknown_name

BUILTIN_DIR = Path(__file__).resolve().parent / "stations"

STATION_KEYS = {
    "id": Key(str, required=True, doc="the station's name in runs and results"),
    "results": Key(str, "runs/results.sqlite", doc="SQLite file or database URL"),
    "runs_dir": Key(str, "runs", doc="folder of the raw files"),
    # the line signs its unit records with this key (docs/line.md); kept out of the repository
    "line_key": Key(str, "", doc="Ed25519 private key file (PEM) signing the line's unit records"),
    "description": Key(str, "", doc="one line for people"),
    "kind": Key(str, "", choices=("", "hrg", "mems-ring"), doc="gyro held: hrg, mems-ring ('' = not said)"),
    # where the sensitive axis points, for Earth's rate on it (docs/noise_model.md)
    "latitude_deg": Key(float, 0.0, -90.0, 90.0, doc="the station's latitude (north > 0)", unit="deg"),
    "axis_elevation_deg": Key(float, 90.0, -90.0, 90.0, doc="sensitive axis above the horizontal (90 = up)",
                              unit="deg"),
    "axis_azimuth_deg": Key(float, 0.0, 0.0, 360.0, doc="sensitive axis from north toward east", unit="deg"),
}
#: the kind of gyro a simulated station holds when its file does not say
PRESET_KINDS = {"hrg": "hrg", "hrg-wa": "hrg", "hrg-selfcal": "hrg", "hrg-selfcal-gains": "hrg", "mems": "mems-ring",
                "hrg-realistic": "hrg", "mems-realistic": "mems-ring"}
SIM_KEYS = {
    "preset": Key(str, "hrg", choices=tuple(PRESET_KINDS),
                  doc="simulated resonator (and its noise)"),
    "seed": Key(int, 0, 0, 2**63 - 1, doc="random seed of the simulation"),
    "speed": Key(float, 0.0, 0.0, 1e6, doc="0 = lockstep, else x real time"),
    "sample_period_s": Key(float, 1e-3, 1e-5, 0.1, doc="simulated sample period", unit="s"),
    "earth_rate": Key(bool, False, doc="simulate Earth's rate on the axis ([station] latitude and axis)"),
}

#: `[nominal]`: what the procedures assume of the gyro (bench.nominal), each key optional
NOMINAL_LIMITS = {"bryan_factor": (0.01, 1.0, ""), "f0_hz": (1.0, 1e6, "Hz"), "pickoff_gain": (0.5, 2.0, ""),
                  "forcer_gain": (0.5, 2.0, "")}
NOMINAL_TABLE_KEYS = {name: Key(float, None, lo, hi, doc=NOMINAL_KEYS[name], unit=unit)
                      for name, (lo, hi, unit) in NOMINAL_LIMITS.items()}


@dataclass
class StationConfig:
    """A checked station file."""

    source: str
    station: dict[str, Any]
    simulation: dict[str, Any] | None
    devices: dict[str, dict[str, Any]] = field(default_factory=dict)
    #: several gyros on one table: each slot's own devices by role (`[slots.N.<role>]`), slot
    #: numbers 1..N; `devices` then holds what the slots share (the table, a switched front end)
    slots: dict[int, dict[str, dict[str, Any]]] = field(default_factory=dict)
    #: the file's `[nominal]` values (only those it sets; bench.nominal has the rest)
    nominal: dict[str, float] = field(default_factory=dict)
    #: `[calibration]`: each device's (or reference's) calibration due date
    calibration: dict[str, datetime.date] = field(default_factory=dict)

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


def _read(path: Path) -> dict[str, Any]:
    """A station file's TOML as a dict; StationError if it is not UTF-8 TOML or cannot be read."""
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise StationError(f"{path}: not valid TOML: {exc}") from None
    except UnicodeDecodeError as exc:
        raise StationError(
            f"{path}: not UTF-8 text (byte 0x{exc.object[exc.start]:02x} at offset {exc.start}); save it as UTF-8"
        ) from None
    except OSError as exc:
        raise StationError(f"{path}: cannot be read: {exc.strerror or exc}") from None


def load_config(name_or_path: str | Path) -> StationConfig:
    """Read and check a station file; StationError names the file, key, value and range."""
    path = find_station_file(name_or_path)
    raw = _read(path)
    for top in raw:
        if top not in ("station", "simulation", "devices", "slots", "nominal", "calibration"):
            raise StationError(f"{path}: unknown table [{top}] (allowed: station, simulation, devices, slots, "
                               "nominal, calibration)")
    if "station" not in raw:
        raise StationError(f'{path}: missing table [station] with id = "..."')
    for top in ("station", "simulation", "devices", "slots", "nominal", "calibration"):
        if top in raw and not isinstance(raw[top], dict):
            raise StationError(f"{path}: {not_a(top, raw[top], 'a table ([' + top + '])')}")
    station = check_table(f"{path}: [station]", raw["station"], STATION_KEYS)
    try:  # the id names runs, records and files: printable, not too long (bench.validation)
        check_label("id", station["id"])
    except ValidationError as exc:
        raise StationError(f"{path}: [station] {exc}") from None
    sim = check_table(f"{path}: [simulation]", raw["simulation"], SIM_KEYS) if "simulation" in raw else None
    devices = {role: _check_device(path, f"[devices.{role}]", role, table, sim)
               for role, table in (raw.get("devices") or {}).items()}
    slots = _check_slots(path, raw.get("slots") or {}, devices, sim)
    if not devices:
        raise StationError(f"{path}: no [devices.*] table (roles: {', '.join(ROLES)})")
    nominal = check_table(f"{path}: [nominal]", raw.get("nominal") or {}, NOMINAL_TABLE_KEYS)
    nominal = {k: v for k, v in nominal.items() if v is not None}
    return StationConfig(source=str(path), station=station, simulation=sim, devices=devices, slots=slots,
                         nominal=nominal, calibration=_check_calibration(path, raw.get("calibration") or {}))


def _check_calibration(path: Path, table: dict[str, Any]) -> dict[str, datetime.date]:
    """`[calibration]`: NAME = due date (a TOML date or an ISO text `2027-03-31`), one per device or
    reference (docs/line.md "Station calibration")."""
    out = {}
    for name, value in table.items():
        if isinstance(value, datetime.datetime):
            value = value.date()
        elif isinstance(value, str):
            try:
                value = datetime.date.fromisoformat(value)
            except ValueError:
                value = None
        if not isinstance(value, datetime.date):
            raise StationError(f"{path}: [calibration] {name} = {table[name]!r} is not a date "
                               f"(e.g. {name} = 2027-03-31)")
        out[name] = value
    return out


def _check_device(path: Path, name: str, role: str, table: Any, sim: dict[str, Any] | None) -> dict[str, Any]:
    """One device table (`[devices.<role>]` or `[slots.N.<role>]`) checked against its driver's keys."""
    where = f"{path}: {name}"
    if role not in ROLES and not role.isidentifier():
        raise StationError(
            f"{where} {role!r} is not a name (roles: {', '.join(ROLES)}, or a name of your "
            f"own, letters, digits and _, for an instrument)"
        )
    if not isinstance(table, dict):
        raise StationError(f"{path}: {not_a(name.strip('[]'), table, 'a table')}")
    driver = table.get("driver")
    kind = role if role in ROLES else INSTRUMENT
    fitting = sorted(n for n, spec in DRIVERS.items() if spec.role == kind)
    if driver is None:
        raise StationError(f"{where} {missing_key('driver', 'one of ' + ', '.join(fitting))}")
    if not isinstance(driver, str) or driver not in DRIVERS:
        raise StationError(f"{where} {not_one_of('driver', driver, fitting)}")
    spec = DRIVERS[driver]
    if kind == INSTRUMENT and spec.role in ROLES:
        raise StationError(
            f"{where} unknown role {role!r}: a {spec.role} driver goes under [devices.{spec.role}] "
            f"(a name of your own holds an instrument: driver = one of {', '.join(fitting)})"
        )
    if spec.role != kind:
        raise StationError(f"{where} {not_one_of('driver', driver, fitting)} (it is a {spec.role} driver)")
    cfg = check_table(where, table, spec.keys)
    if spec.check_config is not None:
        spec.check_config(where, cfg)
    if kind == INSTRUMENT:
        cfg["role"] = role  # the instrument's name in the run, its logged stream and `ctx.devices`
    if sim is None:
        missing = [k for k in ("resource", "url") if k in spec.keys and not cfg.get(k)]
        if missing:
            raise StationError(f"{where} {missing_key(missing[0], 'a real device needs its address')}")
    return cfg


#: the most slots a station file may declare
MAX_SLOTS = 16


def _check_slots(path: Path, raw: Any, shared: dict[str, dict[str, Any]],
                 sim: dict[str, Any] | None) -> dict[int, dict[str, dict[str, Any]]]:
    """`[slots.N.<role>]`: slots numbered 1..N without a gap, each with the same roles, none of
    them the shared table nor a role [devices.*] already shares."""
    if not isinstance(raw, dict):
        raise StationError(f"{path}: {not_a('slots', raw, 'a table of [slots.N] tables')}")
    if not raw:
        return {}
    numbers = []
    for key in raw:
        if not (isinstance(key, str) and key.isdigit() and 1 <= int(key) <= MAX_SLOTS):
            raise StationError(f"{path}: [slots.{key}]: a slot is a number from 1 to {MAX_SLOTS}")
        numbers.append(int(key))
    if sorted(numbers) != list(range(1, len(numbers) + 1)):
        raise StationError(f"{path}: [slots.*] are {sorted(numbers)}: number them 1 to {len(numbers)} without a gap")
    if "table" not in shared:
        raise StationError(f"{path}: [slots.*] need the table they share in [devices.table]")
    slots: dict[int, dict[str, dict[str, Any]]] = {}
    roles_of_1: list[str] | None = None
    for n in sorted(numbers):
        body = raw[str(n)]
        if not isinstance(body, dict) or not body:
            raise StationError(f"{path}: [slots.{n}] holds no device table ([slots.{n}.fpga] ...)")
        for role in body:
            if role == "table":
                raise StationError(f"{path}: [slots.{n}.table]: the slots share one table, [devices.table]")
            if role in shared:
                raise StationError(f"{path}: [slots.{n}.{role}]: {role} is already shared in [devices.{role}]")
        slots[n] = {role: _check_device(path, f"[slots.{n}.{role}]", role, t, sim) for role, t in body.items()}
        roles = sorted(body)
        if roles_of_1 is None:
            roles_of_1 = roles
        elif roles != roles_of_1:
            raise StationError(f"{path}: [slots.{n}] has {roles}, [slots.1] has {roles_of_1}: "
                               "every slot the same roles")
    return slots


def station_problems(name_or_path: str | Path) -> list[str]:
    """Every problem of a station file, one line each, in load_config's words ([] when it loads):
    each key of each table checked on its own, so a file with three mistakes shows three lines.
    Nothing is opened or started (`gyrobench check-station`)."""
    try:
        path = find_station_file(name_or_path)
        raw = _read(path)
    except StationError as exc:
        return [str(exc)]
    problems: list[str] = []
    for top, value in raw.items():
        if top not in ("station", "simulation", "devices", "slots", "nominal", "calibration"):
            problems.append(f"{path}: unknown table [{top}] (allowed: station, simulation, devices, slots, "
                            "nominal, calibration)")
        elif not isinstance(value, dict):
            problems.append(f"{path}: {not_a(top, value, 'a table ([' + top + '])')}")
    tables = {k: v for k, v in raw.items() if isinstance(v, dict)}
    if "station" not in raw:
        problems.append(f'{path}: missing table [station] with id = "..."')
    elif "station" in tables:
        problems += _table_problems(f"{path}: [station]", tables["station"], STATION_KEYS)
        if isinstance(tables["station"].get("id"), str):
            try:
                check_label("id", tables["station"]["id"])
            except ValidationError as exc:
                problems.append(f"{path}: [station] {exc}")
    sim = None
    if "simulation" in tables:
        sim_problems = _table_problems(f"{path}: [simulation]", tables["simulation"], SIM_KEYS)
        problems += sim_problems
        sim = check_table(f"{path}: [simulation]", tables["simulation"], SIM_KEYS) if not sim_problems else {}
    devices: dict[str, dict[str, Any]] = {}
    for role, table in (tables.get("devices") or {}).items():
        try:
            devices[role] = _check_device(path, f"[devices.{role}]", role, table, sim)
        except StationError as exc:
            problems += _device_problems(path, f"[devices.{role}]", role, table) or [str(exc)]
    if raw.get("devices", {}) == {}:  # absent or empty (one that is not a table is said above)
        problems.append(f"{path}: no [devices.*] table (roles: {', '.join(ROLES)})")
    if tables.get("slots"):
        try:
            _check_slots(path, tables["slots"], devices, sim)
        except StationError as exc:
            problems.append(str(exc))
    if tables.get("nominal"):
        problems += _table_problems(f"{path}: [nominal]", tables["nominal"], NOMINAL_TABLE_KEYS)
    if tables.get("calibration"):
        try:
            _check_calibration(path, tables["calibration"])
        except StationError as exc:
            problems.append(str(exc))
    if not problems:
        try:
            load_config(path)
        except StationError as exc:  # a rule across tables the checks above do not repeat
            problems.append(str(exc))
    return list(dict.fromkeys(problems))


def _table_problems(where: str, table: dict[str, Any], keys: dict[str, Key]) -> list[str]:
    """Each unknown, missing or bad key of one table, in check_table's words."""
    out = [f"{where} {unknown_name(name, 'unknown key', keys)}" for name in table if name not in keys]
    for name, key in keys.items():
        if name in table:
            try:
                key.check(where, name, table[name])
            except StationError as exc:
                out.append(str(exc))
        elif key.required:
            out.append(f"{where} {missing_key(name, key.range_text())}")
    return out


def _device_problems(path: Path, name: str, role: str, table: Any) -> list[str]:
    """Each bad key of a device table whose driver is known ([] otherwise: its one error stands)."""
    driver = table.get("driver") if isinstance(table, dict) else None
    spec = DRIVERS.get(driver) if isinstance(driver, str) else None
    if spec is None or spec.role != (role if role in ROLES else INSTRUMENT):
        return []
    return _table_problems(f"{path}: {name}", table, spec.keys)
