"""Stations: a TOML file -> devices (real or simulated) with limits, the safe state, link checks.

A station file names each device by role (`table`, `frontend`, `fpga`) with a `driver` from the
registry below, its address and its limits.  With a `[simulation]` table the station builds one
World (physics preset + seed) and a SimClock, starts each device's simulator on loopback and
points the same drivers at them.  A new instrument model is a new `DriverSpec`, not an engine
change.  Example (`bench/stations/sim-hrg.toml`):

    [station]
    id = "sim-hrg"

    [simulation]
    preset = "hrg"
    seed = 0

    [devices.table]
    driver = "modbus-table"
    max_rate_dps = 1000.0
    max_accel_dps2 = 500.0
"""

from __future__ import annotations

import contextlib
import logging
import math
import threading
import time
import tomllib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from bench.engine.context import GuardedClock
from bench.engine.safety import SafeStateReport, ordered_roles
from bench.validation import KIND_WORDS, ValidationError, convert, missing_key, not_a, not_one_of, unknown_name
from drivers.errors import DeviceError, LinkLostError, SafetyTripError

_log = logging.getLogger(__name__)
BUILTIN_DIR = Path(__file__).resolve().parent / "stations"
ROLES = ("table", "frontend", "fpga")
#: station fault kinds (`--fault KIND@SECONDS`) -> (role, simulator inject kind)
FAULTS: dict[str, tuple[str, str]] = {
    "link-drop": ("fpga", "link-drop"),
    "link-corrupt": ("fpga", "corrupt"),
    "table-estop": ("table", "estop"),
    "table-fault": ("table", "fault"),
    "frontend-hang": ("frontend", "hang"),
}
#: wall seconds a simulated front-end hang lasts (its own watchdog then reboots it)
FRONTEND_HANG_WALL_S = 3.0


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


# --- device registry -------------------------------------------------------------------------
@dataclass(frozen=True)
class DriverSpec:
    """How to build one instrument model's driver and (optionally) its simulator.

    build(cfg, clock) -> connected driver; serve(world, cfg) -> (simulator handle, address keys
    for the driver); health(device) -> optional (n, k) rows for the role's stream, raising
    LinkLostError / SafetyTripError when the device is gone or tripped."""

    name: str
    role: str
    keys: dict[str, Key]
    build: Callable[[dict[str, Any], Any], Any]
    serve: Callable[[Any, dict[str, Any]], tuple[Any, dict[str, Any]]] | None = None
    health: Callable[[Any], Any] | None = None
    doc: str = ""


DRIVERS: dict[str, DriverSpec] = {}


def register_driver(spec: DriverSpec) -> DriverSpec:
    if spec.role not in ROLES:
        raise ValueError(f"driver {spec.name!r}: role {spec.role!r} is not one of {ROLES}")
    DRIVERS[spec.name] = spec
    return spec


def _table_keys(address: dict[str, Key]) -> dict[str, Key]:
    return {
        "driver": Key(str, required=True),
        "max_rate_dps": Key(float, 1000.0, 1e-3, 20000.0, doc="rate limit", unit="deg/s"),
        "max_accel_dps2": Key(float, 500.0, 1e-3, 100000.0, doc="acceleration limit", unit="deg/s^2"),
        "watchdog_s": Key(float, 2.0, 0.1, 60.0, doc="table stops itself without a command for this long", unit="s"),
        "timeout_s": Key(float, 1.0, 0.01, 30.0, doc="wall time allowed for a reply", unit="s"),
        **address,
    }


def _table_health(table: Any) -> np.ndarray:
    st = table.status()
    if st.tripped:
        raise SafetyTripError(f"rate table tripped: {st.trip_reason()}, rate={st.rate_dps:.3f} deg/s")
    return np.array([[st.rate_dps, st.angle_deg]])


def _build_modbus_table(cfg: dict[str, Any], clock: Any) -> Any:
    from drivers.rate_table import TableLimits
    from drivers.rate_table.modbus_driver import ModbusRateTable

    limits = TableLimits(max_rate_dps=cfg["max_rate_dps"], max_accel_dps2=cfg["max_accel_dps2"])
    kw = dict(limits=limits, clock=clock, device_id=cfg["device_id"], timeout_s=cfg["timeout_s"])
    if cfg.get("serial_port"):
        table = ModbusRateTable.rtu(cfg["serial_port"], watchdog_s=cfg["watchdog_s"], **kw)
    else:
        table = ModbusRateTable(cfg["host"], cfg["port"], watchdog_s=cfg["watchdog_s"], **kw)
    table.connect()
    return table


def _serve_modbus_table(world: Any, cfg: dict[str, Any]) -> tuple[Any, dict[str, Any]]:
    from simulators.rate_table import serve_modbus_table

    handle = serve_modbus_table(
        world,
        max_rate_dps=cfg["max_rate_dps"],
        max_accel_dps2=cfg["max_accel_dps2"],
        watchdog_s=cfg["watchdog_s"],
        device_id=cfg["device_id"],
    )
    return handle, {"host": handle.host, "port": handle.port, "serial_port": ""}


register_driver(
    DriverSpec(
        name="modbus-table",
        role="table",
        keys=_table_keys(
            {
                "host": Key(str, "127.0.0.1", doc="Modbus TCP host"),
                "port": Key(int, 502, 1, 65535, doc="Modbus TCP port"),
                "serial_port": Key(str, "", doc="RTU on a serial port instead of TCP"),
                "device_id": Key(int, 1, 0, 247, doc="Modbus unit id"),
            }
        ),
        build=_build_modbus_table,
        serve=_serve_modbus_table,
        health=_table_health,
        doc="rate table, Modbus TCP or RTU",
    )
)


def _build_ascii_table(cfg: dict[str, Any], clock: Any) -> Any:
    from drivers.rate_table import AsciiRateTable, TableLimits

    limits = TableLimits(max_rate_dps=cfg["max_rate_dps"], max_accel_dps2=cfg["max_accel_dps2"])
    table = AsciiRateTable(
        cfg["url"],
        limits=limits,
        clock=clock,
        baudrate=cfg["baudrate"],
        timeout_s=cfg["timeout_s"],
        watchdog_s=cfg["watchdog_s"],
    )
    table.connect()
    return table


def _serve_ascii_table(world: Any, cfg: dict[str, Any]) -> tuple[Any, dict[str, Any]]:
    from simulators.rate_table import serve_ascii_table

    handle = serve_ascii_table(
        world, max_rate_dps=cfg["max_rate_dps"], max_accel_dps2=cfg["max_accel_dps2"], watchdog_s=cfg["watchdog_s"]
    )
    return handle, {"url": handle.url}


register_driver(
    DriverSpec(
        name="ascii-table",
        role="table",
        keys=_table_keys(
            {
                "url": Key(str, "", doc="serial port, pyserial URL or host:port"),
                "baudrate": Key(int, 115200, 300, 4_000_000, doc="serial line speed (bit/s)"),
            }
        ),
        build=_build_ascii_table,
        serve=_serve_ascii_table,
        health=_table_health,
        doc="rate table, ASCII commands over a serial line or TCP",
    )
)


def _build_frontend(cfg: dict[str, Any], clock: Any) -> Any:
    from drivers.frontend import FrontEndLimits, ScpiFrontEnd

    fe = ScpiFrontEnd(
        cfg["resource"],
        clock=clock,
        limits=FrontEndLimits(max_amplitude_v=cfg["max_amplitude_v"]),
        timeout_s=cfg["timeout_s"],
    )
    fe.connect()
    return fe


def _serve_frontend(world: Any, cfg: dict[str, Any]) -> tuple[Any, dict[str, Any]]:
    from simulators.frontend import serve_frontend

    handle = serve_frontend(world, seed=world.seed)
    return handle, {"resource": handle.resource_name}


def _frontend_health(fe: Any) -> None:
    fe.idn  # noqa: B018 - a query that proves the instrument answers


register_driver(
    DriverSpec(
        name="scpi-frontend",
        role="frontend",
        keys={
            "driver": Key(str, required=True),
            "resource": Key(str, "", doc="VISA resource name"),
            "max_amplitude_v": Key(float, 5.0, 0.0, 10.0, doc="drive amplitude limit", unit="V"),
            "timeout_s": Key(float, 2.0, 0.05, 60.0, doc="wall time allowed for a reply", unit="s"),
        },
        build=_build_frontend,
        serve=_serve_frontend,
        health=_frontend_health,
        doc="DAC/ADC front end, SCPI over VISA",
    )
)


def _build_fpga(cfg: dict[str, Any], clock: Any) -> Any:
    from drivers.fpga.link import FpgaLink

    link = FpgaLink(cfg["url"], clock=clock, timeout_s=cfg["timeout_s"])
    link.connect()
    return link


def _serve_fpga(world: Any, cfg: dict[str, Any]) -> tuple[Any, dict[str, Any]]:
    from simulators.fpga import serve_fpga

    handle = serve_fpga(world, seed=world.seed)
    return handle, {"url": handle.url}


class _FpgaHealth:
    """Lost link, or a frame lost or rejected since the run began, is a link fault."""

    def __call__(self, link: Any) -> None:
        if not link.connected:
            raise LinkLostError(f"FPGA link {link.url} lost")
        if getattr(link.clock, "lockstep", False):
            # lockstep: the world waits while the stream catches up to the bench clock, so a
            # link that died is found at this check's simulated time, not whenever the reader
            # thread happens to notice (a real bench's FPGA clock is not the bench's: skipped)
            link.sync(timeout_wall_s=max(1.0, 2.0 * getattr(link, "timeout_s", 1.0)))
        s = link.stats
        base = getattr(link, "_gyrobench_stats0", None)
        if base is None:  # no run stream started: nothing to compare against yet
            return
        if s.dropped > base[0] or s.corrupt > base[1]:
            raise LinkLostError(
                f"FPGA link {link.url}: stream frames lost ({s.dropped - base[0]}) or corrupt ({s.corrupt - base[1]})"
            )
        if s.callback_errors > base[2]:  # the recorder (or a procedure's tap) failed on a block
            raise DeviceError(
                f"FPGA stream: {s.callback_errors - base[2]} block(s) not taken by a subscriber (recorder?); "
                "the raw data would be incomplete"
            )


register_driver(
    DriverSpec(
        name="fpga-link",
        role="fpga",
        keys={
            "driver": Key(str, required=True),
            "url": Key(str, "", doc="serial port or pyserial URL"),
            "timeout_s": Key(float, 1.0, 0.01, 30.0, doc="wall time allowed for a reply", unit="s"),
            "decimation": Key(int, 1, 1, 100000, doc="stream every Nth sample"),
        },
        build=_build_fpga,
        serve=_serve_fpga,
        health=_FpgaHealth(),
        doc="FPGA register link and demodulated stream",
    )
)

STATION_KEYS = {
    "id": Key(str, required=True, doc="the station's name in runs and results"),
    "results": Key(str, "runs/results.sqlite", doc="SQLite file or database URL"),
    "runs_dir": Key(str, "runs", doc="folder of the raw files"),
    "description": Key(str, "", doc="one line for people"),
    "kind": Key(str, "", choices=("", "hrg", "mems-ring"), doc="gyro held: hrg, mems-ring ('' = not said)"),
}
#: the kind of gyro a simulated station holds when its file does not say
PRESET_KINDS = {"hrg": "hrg", "mems": "mems-ring"}
SIM_KEYS = {
    "preset": Key(str, "hrg", choices=("hrg", "mems"), doc="simulated resonator"),
    "seed": Key(int, 0, 0, 2**63 - 1, doc="random seed of the simulation"),
    "speed": Key(float, 0.0, 0.0, 1e6, doc="0 = lockstep, else x real time"),
    "sample_period_s": Key(float, 1e-3, 1e-5, 0.1, doc="simulated sample period", unit="s"),
}


# --- the station ---------------------------------------------------------------------------
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
        if role not in ROLES:
            raise StationError(f"{path}: [devices.{role}] unknown role {role!r} (allowed: {', '.join(ROLES)})")
        if not isinstance(table, dict):
            raise StationError(f"{path}: {not_a(f'devices.{role}', table, 'a table')}")
        name = table.get("driver")
        fitting = sorted(n for n, spec in DRIVERS.items() if spec.role == role)
        if name is None:
            raise StationError(f"{where} {missing_key('driver', 'one of ' + ', '.join(fitting))}")
        if not isinstance(name, str) or name not in DRIVERS:
            raise StationError(f"{where} {not_one_of('driver', name, fitting)}")
        spec = DRIVERS[name]
        if spec.role != role:
            raise StationError(f"{where} {not_one_of('driver', name, fitting)} (it is a {spec.role} driver)")
        cfg = check_table(where, table, spec.keys)
        if sim is None:
            missing = [k for k in ("resource", "url") if k in spec.keys and not cfg.get(k)]
            if missing:
                raise StationError(f"{where} {missing_key(missing[0], 'a real device needs its address')}")
        devices[role] = cfg
    if not devices:
        raise StationError(f"{path}: no [devices.*] table (roles: {', '.join(ROLES)})")
    return StationConfig(source=str(path), station=station, simulation=sim, devices=devices)


class Station:
    """Devices by role, the bench clock, the safe state and the link checks of one station."""

    # a fault is found within 0.5 simulated s: checks come at clock-slice ends (<= 0.1 s apart) once
    # 0.35 s have passed, so at most 0.45 s after the fault (every 4th 0.1 s slice; each check is
    # three device round trips, the largest cost of a lockstep run after the world itself)
    HEALTH_EVERY_SIM_S = 0.35
    HEALTH_EVERY_WALL_S = 0.5

    def __init__(self, config: StationConfig) -> None:
        self.config = config
        self.id = config.id
        self.simulated = config.simulation is not None
        self.devices: dict[str, Any] = {}
        self.clock: GuardedClock = GuardedClock(self._make_clock())
        self._last_health = (-math.inf, -math.inf)
        self._health_rows: list[np.ndarray] = []
        self._ctx: Any = None
        self._lock = threading.RLock()

    @classmethod
    def load(cls, name_or_path: str | Path, **overrides: Any) -> Station:
        """Check a station file and build its (unopened) station; simulated ones become SimStation."""
        config = load_config(name_or_path)
        if config.simulation is not None:
            return SimStation(config, **overrides)
        if overrides:
            options = ", ".join(f"--{k}" for k in sorted(overrides))
            verb = "applies" if len(overrides) == 1 else "apply"
            raise StationError(f"{config.source}: a real station; {options} {verb} only to a simulated one")
        return cls(config)

    def _make_clock(self) -> Any:
        from bench.clock import RealClock

        return RealClock()

    @property
    def seed(self) -> int | None:
        return None

    @property
    def kind(self) -> str:
        """The kind of gyro held (`[station] kind`; a simulated one's preset when not given; '' = unknown)."""
        sim = self.config.simulation
        return self.config.station.get("kind", "") or (PRESET_KINDS.get(sim["preset"], "") if sim else "")

    def limit(self, role: str, key: str) -> float | None:
        """A device's limit from the station file (`max_rate_dps` of the table), None if it has none."""
        value = self.config.devices.get(role, {}).get(key)
        return None if value is None or isinstance(value, (bool, str)) else float(value)

    @property
    def results_url(self) -> str:
        return self.config.station["results"]

    @property
    def runs_dir(self) -> str:
        return self.config.station["runs_dir"]

    # --- lifecycle -------------------------------------------------------------------------
    def open(self) -> Station:
        """Connect every device (starting the simulators first on a simulated station)."""
        try:
            for role, cfg in self.config.devices.items():
                self.devices[role] = DRIVERS[cfg["driver"]].build(self._device_cfg(role, cfg), self.clock)
        except Exception:
            self.close()
            raise
        return self

    def _device_cfg(self, role: str, cfg: dict[str, Any]) -> dict[str, Any]:
        return cfg

    def close(self) -> None:
        for role in reversed(list(self.devices)):
            try:
                self.devices[role].close()
            except Exception:  # noqa: BLE001 - closing must go on
                pass
        self.devices.clear()

    def __enter__(self) -> Station:
        return self.open()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # --- what the engine asks --------------------------------------------------------------
    def truth(self) -> dict[str, float] | None:
        return None

    def describe(self) -> dict[str, Any]:
        return {
            "id": self.id,
            "source": self.config.source,
            "simulated": self.simulated,
            "simulation": self.config.simulation,
            "devices": self.config.devices,
        }

    def check_links(self) -> None:
        """Called at every engine checkpoint: at most every 0.35 s (bench clock) or 0.5 s (wall)
        ask each device for a sign of life; a lost link or a trip raises.  In lockstep only the
        bench clock counts, so a seeded run makes the same device reads and the same arrays."""
        now_sim, now_wall = self.clock.now(), time.monotonic()
        last_sim, last_wall = self._last_health
        wall_due = now_wall - last_wall >= self.HEALTH_EVERY_WALL_S and not getattr(self.clock, "lockstep", False)
        if now_sim - last_sim < self.HEALTH_EVERY_SIM_S and not wall_due:
            return
        self._last_health = (now_sim, now_wall)
        for role in ordered_roles(self.devices):
            spec = DRIVERS[self.config.devices[role]["driver"]]
            if spec.health is None:
                continue
            rows = spec.health(self.devices[role])
            if role == "table" and rows is not None and self._ctx is not None:
                self._ctx.record("table", ("t_s", "rate_dps", "angle_deg"), np.column_stack([[now_sim], rows]))

    def ensure_ready(self) -> None:
        """Before a run: ask every device for a sign of life; a device whose link was lost since
        the last run is reconnected once, and one that still does not answer is reported down
        (LinkLostError naming it), so a run never starts on a link that is already gone."""
        for role in ordered_roles(self.devices):
            spec = DRIVERS[self.config.devices[role]["driver"]]
            if spec.health is None:
                continue
            if getattr(self.devices[role], "_gyrobench_stats0", None) is not None:
                self.devices[role]._gyrobench_stats0 = None  # the last run's frame counts are not this one's
            try:
                spec.health(self.devices[role])
                continue
            except SafetyTripError:
                raise
            except (LinkLostError, DeviceError, OSError) as exc:
                first = exc
            try:
                self._reconnect(role)
                spec.health(self.devices[role])
            except SafetyTripError:
                raise
            except Exception as exc:  # noqa: BLE001 - any failure to reconnect means the device is down
                raise LinkLostError(f"{role} is down: {first}; reconnecting failed: {exc}") from exc
        self._last_health = (-math.inf, -math.inf)

    def start_streams(self, ctx: Any) -> Callable[[], None]:
        """Record the FPGA's stream (if any) into the run; returns the function that stops it."""
        self._ctx = ctx
        self._last_health = (-math.inf, -math.inf)
        link = self.devices.get("fpga")
        if link is None:
            return lambda: setattr(self, "_ctx", None)
        from drivers.fpga.protocol import STREAM_COLUMNS

        columns = tuple(STREAM_COLUMNS)
        unsubscribe = link.subscribe(lambda block: ctx.record("fpga", columns, block))
        link.start_stream(self.config.devices["fpga"]["decimation"])
        s = link.stats  # the counters that count for this run start with its stream
        link._gyrobench_stats0 = (s.dropped, s.corrupt, s.callback_errors)

        def stop() -> None:
            try:
                if link.connected:
                    link.wait_for_sample(float(self.clock.now()), timeout_wall_s=5.0)
                    link.stop_stream()
            finally:
                unsubscribe()
                self._ctx = None

        return stop

    def safe_state(self) -> SafeStateReport:
        """Cut the drive, bring the table to rest, outputs off (SAFE_ORDER); a device that does not
        confirm is reconnected and asked again (a dropped link), up to `attempts` times."""
        report = SafeStateReport(confirmed=True)
        for role in ordered_roles(self.devices):
            report.order.append(role)
            ok = False
            failed: list[str] = []  # every failed attempt stays in the record, even when a retry succeeds
            for attempt in range(3):
                dev = self.devices[role]
                try:
                    if attempt:
                        self._reconnect(role)
                        dev = self.devices[role]
                    with _warnings_of("drivers") as said:  # a driver reports its trouble in its log
                        ok = bool(dev.safe_state())
                    if not ok:
                        why = f" ({'; '.join(said)})" if said else ""
                        failed.append(f"attempt {attempt + 1}: not confirmed by read-back{why}")
                except Exception as exc:  # noqa: BLE001 - the next device must still be made safe
                    failed.append(f"attempt {attempt + 1}: {type(exc).__name__}: {exc}")
                    ok = False
                if ok:
                    break
                time.sleep(0.5 * attempt)
            if failed:
                report.errors[role] = "; ".join(failed)
                if ok:
                    report.errors[role] += f"; confirmed on attempt {attempt + 1} after reconnecting"
                self._note_safe_state_retry(role, ok, attempt + 1, failed)
            report.devices[role] = ok
            report.confirmed = report.confirmed and ok
        return report

    def _note_safe_state_retry(self, role: str, ok: bool, attempts: int, failed: list[str]) -> None:
        """Say on the console and in the run's log how a device's safe state went after a failure."""
        if ok:
            msg = f"safe state: {role} confirmed on attempt {attempts}, after reconnecting ({failed[0]})"
        else:
            msg = f"safe state: {role} NOT confirmed after {attempts} attempts ({'; '.join(failed)})"
        _log.warning(msg)
        ctx = self._ctx
        if ctx is not None:
            try:
                ctx.log.warning(msg)
            except Exception:  # noqa: BLE001 - a log line must not stop the safe state
                pass

    def _reconnect(self, role: str) -> None:
        dev = self.devices[role]
        try:
            dev.close()
        except Exception:  # noqa: BLE001
            pass
        cfg = self.config.devices[role]
        self.devices[role] = DRIVERS[cfg["driver"]].build(self._device_cfg(role, cfg), self.clock)


@contextlib.contextmanager
def _warnings_of(logger_name: str):
    """The warnings a logger (and its children) emits inside the block, as a list of texts."""
    said: list[str] = []

    class _Keep(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            said.append(record.getMessage())

    handler = _Keep(logging.WARNING)
    logger = logging.getLogger(logger_name)
    logger.addHandler(handler)
    try:
        yield said
    finally:
        logger.removeHandler(handler)


class _FaultScheduler:
    """A World device that injects station faults at given simulated seconds (block-aligned)."""

    def __init__(self, station: SimStation) -> None:
        self.station = station
        self.pending: list[tuple[float, str]] = []
        self.fired: list[tuple[float, str]] = []

    def add(self, kind: str, at_s: float) -> None:
        self.pending.append((float(at_s), kind))
        self.pending.sort()

    def max_block_samples(self, world: Any) -> int | None:
        if not self.pending:
            return None
        left = self.pending[0][0] - world.t_s
        return max(1, int(math.ceil(left / world.sample_period_s - 1e-9)))

    def before_block(self, world: Any, t_s: float, n: int, dt_s: float) -> None:
        while self.pending and self.pending[0][0] <= t_s + 1e-9:
            at, kind = self.pending.pop(0)
            self.station.inject(kind)
            self.fired.append((t_s, kind))

    def after_block(self, world: Any, block: Any) -> None:
        pass


class SimStation(Station):
    """A simulated station: one World + SimClock, the simulators on loopback, the real drivers.

    `truth()` gives the true parameters (same names as the measurements); `inject(kind)` and
    `schedule_fault(kind, at_s)` give the `--fault` kinds of FAULTS."""

    def __init__(
        self,
        config: StationConfig | str | Path = "sim-hrg",
        *,
        seed: int | None = None,
        speed: float | None = None,
        preset: str | None = None,
    ) -> None:
        if not isinstance(config, StationConfig):
            config = load_config(config)
        if config.simulation is None:
            raise StationError(f"{config.source}: not a simulated station (no [simulation] table)")
        sim = dict(config.simulation)
        # overrides come from the command line or the window, not the file: name the option
        if seed is not None:
            sim["seed"] = SIM_KEYS["seed"].check("", "--seed", seed)
        if speed is not None:
            try:
                sim["speed"] = SIM_KEYS["speed"].check("", "--speed", speed)
            except StationError as exc:
                raise StationError(f"{exc} (allowed: 0 = lockstep, or 0 to 1e6 x real time)") from None
        if preset is not None:
            sim["preset"] = SIM_KEYS["preset"].check("", "preset", preset)
        config = StationConfig(config.source, config.station, sim, config.devices)
        from simulators.physics.params import preset as make_preset
        from simulators.world import World

        self.world = World(make_preset(sim["preset"]), seed=sim["seed"], sample_period_s=sim["sample_period_s"])
        self.handles: dict[str, Any] = {}
        self.addresses: dict[str, dict[str, Any]] = {}
        self.faults = _FaultScheduler(self)
        self.world.attach(self.faults)
        self._timers: list[threading.Timer] = []
        super().__init__(config)

    def _make_clock(self) -> Any:
        from bench.clock import SimClock

        speed = self.config.simulation["speed"]
        return SimClock(self.world, speed=math.inf if speed == 0 else speed)

    @property
    def seed(self) -> int:
        return int(self.config.simulation["seed"])

    def start_simulators(self) -> dict[str, dict[str, Any]]:
        """Start each device's simulator on loopback; their addresses by role."""
        for role, cfg in self.config.devices.items():
            spec = DRIVERS[cfg["driver"]]
            if spec.serve is None:
                raise StationError(f"{self.config.source}: [devices.{role}] driver {spec.name!r} has no simulator")
            if role not in self.handles:
                self.handles[role], self.addresses[role] = spec.serve(self.world, cfg)
        return self.addresses

    def open(self) -> SimStation:
        try:
            self.start_simulators()
        except Exception:
            self.close()
            raise
        super().open()
        return self

    def _device_cfg(self, role: str, cfg: dict[str, Any]) -> dict[str, Any]:
        return {**cfg, **self.addresses.get(role, {})}

    def close(self) -> None:
        super().close()
        for t in self._timers:
            t.cancel()
        for handle in self.handles.values():
            try:
                handle.stop()
            except Exception:  # noqa: BLE001
                pass
        self.handles.clear()
        self.clock.close()

    def truth(self) -> dict[str, float]:
        return self.world.truth()

    def describe(self) -> dict[str, Any]:
        d = super().describe()
        d["addresses"] = self.addresses
        return d

    # --- faults ----------------------------------------------------------------------------
    def inject(self, kind: str) -> None:
        """Inject a station fault now (one of FAULTS)."""
        if kind not in FAULTS:
            raise StationError(f"fault {kind!r} is not one of {', '.join(FAULTS)}")
        role, sim_kind = FAULTS[kind]
        handle = self.handles.get(role)
        if handle is None:
            raise StationError(f"fault {kind!r}: this station has no simulated {role}")
        if kind == "link-corrupt":
            handle.inject(sim_kind, 0.05)
        else:
            handle.inject(sim_kind)
        if kind == "frontend-hang":
            timer = threading.Timer(FRONTEND_HANG_WALL_S, handle.inject, args=("none",))
            timer.daemon = True
            timer.start()
            self._timers.append(timer)

    def schedule_fault(self, kind: str, at_s: float) -> None:
        """Inject `kind` when the world reaches `at_s` simulated seconds."""
        if kind not in FAULTS:
            raise StationError(f"fault {kind!r} is not one of {', '.join(FAULTS)}")
        if not (math.isfinite(at_s) and at_s >= 0):
            raise StationError(f"fault {kind!r} at {at_s!r} s: the time must be >= 0")
        if FAULTS[kind][0] not in self.config.devices:
            raise StationError(f"--fault {kind}: station {self.id!r} has no {FAULTS[kind][0]} to fault")
        with self.world.lock:
            self.faults.add(kind, at_s)


def parse_fault(text: str) -> tuple[str, float]:
    """`KIND@SECONDS` -> (kind, seconds)."""
    kind, sep, at = text.partition("@")
    if not sep:
        raise StationError(f"--fault {text!r}: expected KIND@SECONDS, e.g. link-drop@2.5")
    if kind not in FAULTS:
        raise StationError(f"--fault {text!r}: kind {kind!r} is not one of {', '.join(FAULTS)}")
    try:
        at_s = float(at)
    except ValueError:
        raise StationError(f"--fault {text!r}: {at!r} is not a number of seconds") from None
    try:
        at_s = convert("time", at_s, float, low=0.0, unit="s")
    except ValidationError as exc:
        raise StationError(f"--fault {text!r}: {exc}") from None
    return kind, at_s


# --- instrument models that declare their own station entry next to their driver (issue 22) --
from drivers.frontend import sr865_spec  # noqa: E402,F401
from drivers.rate_table import acutronic_spec  # noqa: E402,F401
