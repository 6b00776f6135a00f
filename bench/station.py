"""Stations: the lifecycle of one station's devices -- open/close, link checks, streams, the safe state.

A station file (bench.station_config) names each device by role (`table`, `frontend`, `fpga`) with
a `driver` from the registry (bench.devices), its address and its limits.  Everything about a
model lives in its spec next to its driver (`drivers/<kind>/<model>_spec.py`): keys, build,
health, stream, safe-state step and part.  This module only composes them and never names a role
or a model: a new rate-table model is one new spec file (+ its simulator), a second FPGA or N
front ends are more `[devices.*]` entries whose specs say the same parts.  The safe-state order is
the engine's rule (bench.devices.SAFE_PARTS: every drive cut, then the table to rest, then
every output off); each part is a list of devices, so the several-gyros station makes every
slot's drive safe before the shared table is brought to rest.  With a `[simulation]` table the
station is a `bench.composition.sim_station.SimStation` (World + SimClock, simulators on loopback,
faults of simulators.faults), built by the composition root `bench.composition.load_station`.
Example (`bench/stations/sim-hrg.toml`):

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
from collections.abc import Callable
from typing import Any

import numpy as np

from bench.devices import DRIVERS, DriverSpec, StreamSpec, close_devices
from bench.engine.context import GuardedClock
from bench.engine.safety import SafeStateReport, by_part
from bench.station_config import PRESET_KINDS, StationConfig
from drivers.errors import DeviceError, LinkLostError, SafetyTripError

_log = logging.getLogger(__name__)
class Station:
    """Devices by role, the bench clock, the safe state and the link checks of one station."""

    # a fault is found within 0.5 simulated s: in lockstep the checks run at every point of the
    # clock's grid (GuardedClock.LOCKSTEP_GRID_S = 0.4 s, where its waits stop), in real time at
    # clock-slice ends (<= 0.1 s apart) once 0.35 s or 0.5 wall s have passed
    HEALTH_EVERY_SIM_S = 0.35
    HEALTH_EVERY_WALL_S = 0.5
    #: the link checks' rows go to the run in blocks of at most this many rows or this much wall
    #: time (in lockstep thousands of checks a run; each its own event cost more than the check)
    HEALTH_BLOCK_ROWS = 32
    HEALTH_BLOCK_WALL_S = 0.2
    #: ... or this much bench time: at "max" 32 rows are 12.8 s, and the window's table curve
    #: trailed its FPGA curves by that much (the FPGA's blocks are a grid step long)
    HEALTH_BLOCK_SIM_S = 2.0

    def __init__(self, config: StationConfig) -> None:
        self.config = config
        self.id = config.id
        self.simulated = config.simulation is not None
        self.devices: dict[str, Any] = {}
        self.clock: GuardedClock = GuardedClock(self._make_clock())
        self._last_health = (-math.inf, -math.inf)
        self._health_rows: dict[str, tuple[tuple[str, ...], list[np.ndarray]]] = {}  # role: rows not yet recorded
        self._health_sent_wall = -math.inf
        self._roles_cache: tuple[tuple[str, ...], list[str]] | None = None
        self._ctx: Any = None
        self._lock = threading.RLock()
        #: each streaming device's counters (lost/corrupt frames...) when this run's stream began, by role
        self._stream_since: dict[str, Any] = {}

    def spec(self, role: str) -> DriverSpec:
        """The spec of the model this station's `role` uses."""
        return DRIVERS[self.config.devices[role]["driver"]]

    def safe_state_plan(self) -> list[tuple[str, list[str]]]:
        """(part, roles) in the engine's order (SAFE_PARTS); each device's part comes from its spec."""
        return by_part({role: self.spec(role).part for role in self.devices})

    def _ordered_roles(self) -> list[str]:
        """The open devices in safe-state order (also the order of the link checks; kept per set
        of roles, as a lockstep run checks thousands of times)."""
        key = tuple(self.devices)
        cached = self._roles_cache
        if cached is None or cached[0] != key:
            cached = self._roles_cache = (key, [role for _, roles in self.safe_state_plan() for role in roles])
        return list(cached[1])

    def _health_roles(self) -> list[str]:
        """The devices this station's link checks ask (a slot of a batch: its own only)."""
        return self._ordered_roles()

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

    @property
    def nominal(self) -> dict[str, float]:
        """What procedures assume of the gyro held: bench.nominal's values for its kind, the
        file's `[nominal]` over them (never the simulated unit's truth)."""
        from bench.nominal import nominal_for

        return nominal_for(self.kind, self.config.nominal)

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
        """Connect every device (starting the simulators first on a simulated station); an open
        station stays as it is (`with station.open() as st` opens once)."""
        if self.devices:
            return self
        try:
            for role, cfg in self.config.devices.items():
                self.devices[role] = self.spec(role).build(self._device_cfg(role, cfg), self.clock)
        except Exception:
            self.close()
            raise
        return self

    def _device_cfg(self, role: str, cfg: dict[str, Any]) -> dict[str, Any]:
        return cfg

    def close(self) -> None:
        close_devices(self.devices)

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
            "keys": self.config.station,  # [station]: kind, latitude and sensitive axis, ...
        }

    def check_links(self) -> None:
        """Called at every engine checkpoint: at most every 0.35 s (bench clock) or 0.5 s (wall)
        ask each device for a sign of life; a lost link or a trip raises.  In lockstep only the
        bench clock counts, so a seeded run makes the same device reads and the same arrays."""
        now_sim, now_wall = self.clock.now(), time.monotonic()
        last_sim, last_wall = self._last_health
        if getattr(self.clock, "lockstep", False):  # once per grid point (the clock's waits stop there)
            grid = self.clock.LOCKSTEP_GRID_S
            if last_sim > -math.inf and math.floor(now_sim / grid + 1e-9) <= math.floor(last_sim / grid + 1e-9):
                return
        elif now_sim - last_sim < self.HEALTH_EVERY_SIM_S and now_wall - last_wall < self.HEALTH_EVERY_WALL_S:
            return
        self._last_health = (now_sim, now_wall)
        # a streaming link's check waits for its reader to catch up with the clock: checked first,
        # so the reader works through the frames while this thread waits, and the other links'
        # round trips after it do not wait for the GIL behind the reader (a stable order)
        roles = self._health_roles()
        for role in [r for r in roles if self.spec(r).stream] + [r for r in roles if self.spec(r).stream is None]:
            spec = self.spec(role)
            if spec.health is None:
                continue
            device = self.devices[role]
            rows = spec.health(device, self._stream_since.get(role))
            columns = spec.health_columns or getattr(device, "health_columns", ())  # an instrument's own
            if columns and rows is not None and self._ctx is not None:
                pending = self._health_rows.setdefault(role, (("t_s", *columns), []))[1]
                pending.append(np.column_stack([[now_sim], rows]))
        if self._health_rows and (
            now_wall - self._health_sent_wall >= self.HEALTH_BLOCK_WALL_S
            or max(len(rows) for _, rows in self._health_rows.values()) >= self.HEALTH_BLOCK_ROWS
            or now_sim - min(rows[0][0, 0] for _, rows in self._health_rows.values()) >= self.HEALTH_BLOCK_SIM_S
        ):
            self._send_health_rows()

    def _send_health_rows(self) -> None:
        """Record the link checks' rows not yet recorded, one block per device."""
        pending, self._health_rows = self._health_rows, {}
        self._health_sent_wall = time.monotonic()
        if self._ctx is None:
            return
        for role, (columns, rows) in pending.items():
            self._ctx.record(role, columns, np.concatenate(rows))

    def ensure_ready(self) -> None:
        """Before a run: ask every device for a sign of life; a device whose link was lost since
        the last run is reconnected once, and one that still does not answer is reported down
        (LinkLostError naming it), so a run never starts on a link that is already gone."""
        self._stream_since.clear()  # the last run's frame counts are not this one's
        for role in self._ordered_roles():
            spec = self.spec(role)
            if spec.health is None:
                continue
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
        """Record every device stream (the FPGA's, N links' on a several-gyros station) into the run
        under its role; returns the function that stops them."""
        self._ctx = ctx
        self._last_health = (-math.inf, -math.inf)
        self._health_rows = {}
        started: list[tuple[Any, StreamSpec, Callable[[], None]]] = []
        try:
            for role, dev in self.devices.items():
                stream = self.spec(role).stream
                if stream is None:
                    continue
                columns = stream.columns
                unsubscribe = dev.subscribe(lambda block, role=role, columns=columns: ctx.record(role, columns, block))
                started.append((dev, stream, unsubscribe))
                stream.start(dev, self.config.devices[role])
                if stream.counters is not None:  # the counters that count for this run start with its stream
                    self._stream_since[role] = stream.counters(dev)
        except BaseException:
            self._stop_streams(started)
            raise

        def stop() -> None:
            self._stop_streams(started)

        return stop

    def _stop_streams(self, started: list[tuple[Any, StreamSpec, Callable[[], None]]]) -> None:
        """Stop each started stream (once the data reach the bench clock's time) and unsubscribe, every
        one whatever the others do; the first failure is raised at the end."""
        first: BaseException | None = None
        for dev, stream, unsubscribe in started:  # the device the stream was started on (not a reconnected one)
            try:
                stream.stop(dev, self.clock)
            except BaseException as exc:  # noqa: BLE001 - the next stream must still stop
                first = first or exc
            finally:
                unsubscribe()
        started.clear()
        try:
            self._send_health_rows()
        except BaseException as exc:  # noqa: BLE001 - raised below, after the streams are let go
            first = first or exc
        self._ctx = None
        if first is not None:
            raise first

    def safe_state(self) -> SafeStateReport:
        """Cut the drive, bring the table to rest, outputs off (SAFE_PARTS, each device's part from its
        spec); a device that does not confirm is reconnected and asked again (a dropped link), up to 3 times."""
        report = SafeStateReport(confirmed=True)
        for role in self._ordered_roles():
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
                        ok = bool(self.spec(role).safe_state(dev))
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
        self.devices[role] = self.spec(role).build(self._device_cfg(role, cfg), self.clock)


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
