"""The window on a real engine: a station (built-in name or file), the Runner in a worker
thread, the procedures of the registry.  The runner's events go to the window through the bus;
the station panel's StationStatus is built here from what needs no device I/O (the table stream,
link counters, connection flags), so the GUI never talks to an instrument across threads."""

from __future__ import annotations

import logging
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from bench.engine import events as ev
from bench.engine.params import Param

from .manual_backend import ManualBackendMixin

DEFAULT_STATION = "sim-hrg"
STATUS_EVERY_WALL_S = 0.5
POLL_HZ = 2.0  # the station panel's refresh from the devices: modest, the links are the run's first


def default_station() -> str:
    return DEFAULT_STATION


log = logging.getLogger(__name__)

class EngineBackend(ManualBackendMixin):
    """GuiBackend over `bench.engine.Runner` on a `bench.station.Station` (opened here)."""

    def __init__(self, station: str, *, seed: int | None = None, runs_dir: str | Path | None = None,
                 results_url: str | None = None, record: bool = True) -> None:
        from bench.composition import load_station
        from bench.composition.sim_station import SimStation
        from bench.engine import Runner

        overrides = {"seed": seed} if seed is not None else {}
        self.station = load_station(station, **overrides)
        self.simulated = isinstance(self.station, SimStation)
        self.station_name = self.station.id
        self.bus = ev.EventBus()
        store = None
        if record:
            try:
                from bench.results import ResultsStore

                store = ResultsStore(results_url or self.station.results_url, offline_ok=True)  # down: spool
            except Exception:  # noqa: BLE001 - the window works without an index
                store = None
        self.runs_dir = Path(runs_dir or self.station.runs_dir) if record else None
        self.runner = Runner(self.station, bus=self.bus, runs_dir=self.runs_dir, store=store)
        self._thread: threading.Thread | None = None
        self._table_row: tuple[float, float] | None = None
        self._last_status_wall = 0.0
        self._in_run = False  # set before the run's thread starts, cleared once its safe state is done
        self._io_gate = threading.Lock()  # a panel read and a run's start never overlap on a device
        self._poll_stop = threading.Event()
        self._poller: threading.Thread | None = None
        self.bus.subscribe(self._watch)
        self.station.open()
        self.publish_status()

    # --- GuiBackend ------------------------------------------------------------------------
    def procedures(self) -> dict[str, tuple[Param, ...]]:
        """The procedures this station can run, with their parameters (the picker omits the others;
        `unavailable()` says why)."""
        from procedures import all_procedures

        refused = self.unavailable()
        return {
            name: tuple(cls.param_specs().values())
            for name, cls in all_procedures().items()
            if name not in refused
        }

    def unavailable(self) -> dict[str, str]:
        """Procedures not offered on this station, with the reason: another kind of gyro, or a
        device role the station lacks."""
        from bench.engine.demands import kind_refusal
        from procedures import all_procedures

        out: dict[str, str] = {}
        for name, cls in all_procedures().items():
            missing = [r for r in cls.requires if r not in self.station.config.devices]
            why = kind_refusal(cls.kinds, self.station.kind)
            if why is None and missing:
                why = f"it needs device role(s) {missing}"
            if why is not None:
                out[name] = why
        return out

    def set_unit(self, duts: list[str], operator: str) -> None:
        """The serials under test and the operator the next run is stored with (history, reports)."""
        if self.running():
            raise RuntimeError(self.busy_text() or "a run is already going on")
        self.runner.duts = list(duts)
        self.runner.operator = operator

    def start(self, procedure: str, values: dict[str, Any]) -> None:
        from bench.engine import check_station
        from procedures import find_procedure

        if self.running():
            raise RuntimeError(self.busy_text() or "a run is already going on")
        proc = find_procedure(procedure)(values)  # ParamError (a ValueError) before anything moves
        check_station(proc, self.station)  # StationMismatch (a ValueError): another kind, or above a limit
        with self._io_gate:  # waits for a panel read in progress: from here on only the run talks to devices
            self._in_run = True
        self._thread = threading.Thread(target=self._run, args=(proc,), name=f"run-{procedure}", daemon=True)
        self._thread.start()

    def _run(self, proc: Any) -> None:
        try:
            self.runner.run(proc)
        except Exception as exc:  # noqa: BLE001 - the runner reports its own failures; this is the rest
            self.bus.publish(ev.Log("", self.station.clock.now(), level="ERROR", message=f"run failed: {exc}"))
        self._in_run = False
        self._table_row = None  # the stream's last row is the run's, not the table's now
        self.publish_status()  # read from the devices: the state the safe state left

    def pause(self) -> None:
        self.runner.pause()

    def resume(self) -> None:
        self.runner.resume()

    def abort(self) -> None:
        self.runner.abort("abort from the window")

    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def set_speed(self, speed: float) -> None:
        self.station.clock.set_speed(speed)

    def join(self, timeout_s: float = 30.0) -> bool:
        if self._thread is not None:
            self._thread.join(timeout_s)
        return not self.running()

    def start_polling(self, hz: float = POLL_HZ) -> None:
        """Refresh the station panel from the devices `hz` times a second in a worker thread (also
        between runs); its StationStatus reaches the window through the bus and the bridge."""
        if self._poller is not None:
            return
        self._poll_stop.clear()

        def loop() -> None:
            while not self._poll_stop.wait(1.0 / hz):
                try:
                    self.publish_status()
                except Exception as exc:  # noqa: BLE001 - the panel must not take the window down
                    log.debug("station panel refresh failed: %s", exc)

        self._poller = threading.Thread(target=loop, name="station-panel", daemon=True)
        self._poller.start()

    def stop_polling(self) -> None:
        self._poll_stop.set()
        if self._poller is not None:
            self._poller.join(5.0)
            self._poller = None

    def close(self) -> None:
        self.stop_polling()
        if self.running():
            self.abort()
            # the run's own safe state must finish before its devices close: a slow ramp-down
            # of a real table takes as long as it takes (the window says so while it waits)
            while not self.join(30.0):
                log.warning("waiting for the run to reach its safe state before closing the station")
        self.station.close()
        clock = getattr(self.station.clock, "close", None)
        if clock is not None:
            clock()

    # --- station panel ---------------------------------------------------------------------
    def _watch(self, event: ev.Event) -> None:
        """Engine thread: keep the table's last row; publish a StationStatus at each step
        boundary and every STATUS_EVERY_WALL_S in between."""
        if isinstance(event, ev.SampleBlock) and event.stream == "table" and len(event.data):
            cols = event.columns
            if "rate_dps" in cols and "angle_deg" in cols:
                row = np.asarray(event.data)[-1]
                self._table_row = (float(row[cols.index("rate_dps")]), float(row[cols.index("angle_deg")]))
        if isinstance(event, ev.StationStatus):
            return
        if isinstance(event, ev.RunFinished):  # the safe state is done: read it from the devices, in the
            self._table_row = None  # run's own thread, before the window hears of the end (never the run's rows)
            self.publish_status(event.run_id, talk=True)
            return
        at_step = isinstance(event, (ev.RunStarted, ev.StepStarted, ev.StepFinished))
        if at_step or time.monotonic() - self._last_status_wall > STATUS_EVERY_WALL_S:
            self.publish_status(event.run_id)

    def publish_status(self, run_id: str = "", *, talk: bool | None = None) -> None:
        """Publish the station panel's state.  Between runs it is read from the devices (table
        status, drive outputs, link counters); during a run only what needs no device I/O (the
        run's own table readings, link counters), so the run's transactions are never interleaved."""
        self._last_status_wall = time.monotonic()
        with self._io_gate:
            devices = self._read_devices(talk=not self._in_run if talk is None else talk)
        self.bus.publish(ev.StationStatus(run_id, self.station.clock.now(), devices=devices))

    def _read_devices(self, *, talk: bool) -> dict[str, dict[str, Any]]:
        devices: dict[str, dict[str, Any]] = {}
        for role, cfg in self.station.config.devices.items():
            dev = self.station.devices.get(role)
            info: dict[str, Any] = {"connected": bool(dev is not None and getattr(dev, "connected", True)),
                                    "driver": cfg.get("driver", "?")}
            try:
                if dev is not None:
                    info.update(_read_device(role, dev, talk=talk))
            except Exception as exc:  # noqa: BLE001 - a device that does not answer is shown down
                info["connected"] = False
                info["error"] = str(exc) or type(exc).__name__
            if role == "table" and "rate_dps" not in info and self._table_row is not None:
                info["rate_dps"], info["angle_deg"] = self._table_row
            devices[role] = info
        return devices


def _read_device(role: str, dev: Any, *, talk: bool) -> dict[str, Any]:
    """What the panel shows of one device; `talk` allows queries over its link."""
    out: dict[str, Any] = {}
    stats = getattr(dev, "stats", None)
    if stats is not None and not callable(stats):  # the FPGA link's counters (no I/O)
        out.update(frames=int(stats.frames), lost=int(stats.dropped), crc_errors=int(stats.corrupt))
    if not talk:
        return out
    if role == "table":
        st = dev.status()
        out.update(rate_dps=float(st.rate_dps), angle_deg=float(st.angle_deg), enabled=bool(st.enabled))
        if st.tripped:
            out["tripped"] = st.trip_reason()
    elif role == "frontend" and hasattr(dev, "channels"):
        out["drive"] = any(bool(c.output_on) for c in dev.channels.values())
    elif callable(getattr(dev, "panel_values", None)):  # an instrument: its logged properties
        out.update(dev.panel_values())
    return out
