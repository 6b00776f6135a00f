"""A small real event source for the window: the HRG world stepping in a worker thread.

Used until a station's engine is attached, and by the GUI's own tests and benchmark: the World
is integrated for real (the averaged HRG model at 1 kHz) and the samples are published as the
engine's SampleBlock events, so the window sees exactly the stream the engine will send.
"""

from __future__ import annotations

import math
import threading
import uuid
from typing import Any

import numpy as np

from bench.analysis.slow_model import orbit_elements, state_from_elements
from bench.clock import SimClock
from bench.engine import events as ev
from simulators.physics.params import preset
from simulators.world import World

from .params import ParamSpec

DECAY_PARAMS = (
    ParamSpec("duration_s", "float", "s", 60.0, 0.1, 3600.0, doc="length of the free decay"),
    ParamSpec("rate_dps", "float", "deg/s", 100.0, -1000.0, 1000.0, doc="table rate during the decay"),
    ParamSpec("block_s", "float", "s", 0.1, 0.001, 1.0, doc="samples per published block"),
)
SWEEP_PARAMS = (
    ParamSpec("span_hz", "float", "Hz", 0.02, 1e-4, 10.0, doc="frequency span around f0"),
    ParamSpec("points", "int", "", 41, 3, 1001, doc="frequencies in the sweep"),
    ParamSpec("dwell_s", "float", "s", 0.2, 0.01, 60.0, doc="time at each frequency"),
)


class _Aborted(Exception):
    pass


class _StreamTap:
    """World device: holds the table rate and the drive, publishes each block's samples."""

    def __init__(self, backend: SimWorldBackend) -> None:
        self.backend = backend
        self.rate_dps = 0.0
        self.ref_freq_hz: float | None = None
        self.publishing = True

    def before_block(self, world: World, t_s: float, n: int, dt_s: float) -> None:
        world.case_rate_dps = self.rate_dps
        if self.ref_freq_hz is not None:
            world.ref_freq_hz = self.ref_freq_hz

    def after_block(self, world: World, block) -> None:
        b = self.backend
        if b.run_id is None or not self.publishing:
            return
        q = block.q_meas
        fpga = np.column_stack((block.t_s, q))
        table = np.column_stack((block.t_s, block.rate_dps, block.angle_deg))
        t = float(block.t_s[-1])
        b.bus.publish(ev.SampleBlock(b.run_id, t, stream="fpga", columns=("t_s", "cx", "sx", "cy", "sy"), data=fpga))
        b.bus.publish(ev.SampleBlock(b.run_id, t, stream="table", columns=("t_s", "rate_dps", "angle_deg"), data=table))


class SimWorldBackend:
    """GuiBackend over an in-process HRG World: procedures `demo-decay` and `demo-sweep`."""

    simulated = True

    def __init__(self, *, seed: int = 0, speed: float = math.inf, station_name: str = "sim-world") -> None:
        self.bus = ev.EventBus()
        self.station_name = station_name
        self.params = preset("hrg")
        self.world = World(self.params, seed=seed)
        self.clock = SimClock(self.world, speed=speed)
        self.tap = _StreamTap(self)
        self.world.attach(self.tap)
        self.run_id: str | None = None
        self._thread: threading.Thread | None = None
        self._abort = threading.Event()
        self._resume = threading.Event()
        self._resume.set()

    # --- GuiBackend ------------------------------------------------------------------------
    def procedures(self) -> dict[str, tuple[ParamSpec, ...]]:
        return {"demo-decay": DECAY_PARAMS, "demo-sweep": SWEEP_PARAMS}

    def start(self, procedure: str, values: dict[str, Any]) -> None:
        specs = self.procedures().get(procedure)
        if specs is None:
            raise ValueError(f"procedure {procedure!r} is not one of {', '.join(self.procedures())}")
        if self.running():
            raise RuntimeError("a run is already going on")
        parsed = {s.name: s.parse(s.format(values.get(s.name, s.default))) for s in specs}
        self._abort.clear()
        self._resume.set()
        self.tap.publishing = True
        run_id = uuid.uuid4().hex[:12]
        target = self._run_decay if procedure == "demo-decay" else self._run_sweep
        self._thread = threading.Thread(target=self._run, args=(run_id, procedure, parsed, target),
                                        name=f"run-{procedure}", daemon=True)
        self._thread.start()

    def pause(self) -> None:
        self._resume.clear()

    def resume(self) -> None:
        self._resume.set()

    def abort(self) -> None:
        self._abort.set()
        self._resume.set()

    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def set_speed(self, speed: float) -> None:
        self.clock.set_speed(speed)

    def join(self, timeout_s: float = 10.0) -> bool:
        if self._thread is not None:
            self._thread.join(timeout_s)
        return not self.running()

    def close(self) -> None:
        self.abort()
        self.join()
        self.clock.close()

    # --- the run ---------------------------------------------------------------------------
    def _run(self, run_id: str, procedure: str, values: dict[str, Any], target) -> None:
        steps = ("settle", "measure", "safe state")
        self.run_id = run_id
        pub = self.bus.publish
        pub(ev.RunStarted(run_id, self.clock.now(), procedure=procedure, params=values,
                          station=self.station_name, simulated=True, steps=steps))
        outcome, reason = "COMPLETE", "finished"
        try:
            pub(ev.StepStarted(run_id, self.clock.now(), name="settle", index=0, total=3, title="Set up"))
            self.world.resonator.set_state(state_from_elements(1.0, 0.0, 0.0))
            pub(ev.StepFinished(run_id, self.clock.now(), name="settle", index=0))
            pub(ev.StepStarted(run_id, self.clock.now(), name="measure", index=1, total=3, title=procedure))
            outcome = target(run_id, values)
            pub(ev.StepFinished(run_id, self.clock.now(), name="measure", index=1))
        except _Aborted:
            outcome, reason = "ABORTED", "aborted by the operator"
            pub(ev.StepFinished(run_id, self.clock.now(), name="measure", index=1, status="aborted"))
        except Exception as exc:  # noqa: BLE001 - the run ends in ERROR and still goes safe
            outcome, reason = "ERROR", f"{type(exc).__name__}: {exc}"
            pub(ev.Log(run_id, self.clock.now(), level="ERROR", message=reason))
        pub(ev.StepStarted(run_id, self.clock.now(), name="safe state", index=2, total=3, title="Safe state"))
        safe = self._safe_state()
        pub(ev.StepFinished(run_id, self.clock.now(), name="safe state", index=2, status="done" if safe else "error"))
        self._publish_status(run_id)
        pub(ev.RunFinished(run_id, self.clock.now(), outcome=outcome, end_reason=reason, safe_state=safe))
        self.run_id = None

    def _safe_state(self) -> bool:
        """Table to rest, drive off; confirmed by reading the world back after a block."""
        self.tap.publishing = False
        self.tap.rate_dps = 0.0
        self.tap.ref_freq_hz = None
        self.world.set_force("drive", None)
        self.world.advance(self.world.sample_period_s)
        with self.world.lock:
            return self.world.case_rate_dps == 0.0 and not np.any(self.world.total_force)

    def _publish_status(self, run_id: str) -> None:
        with self.world.lock:
            rate, angle = self.world.case_rate_dps, self.world.case_angle_deg % 360.0
            drive = bool(np.any(self.world.total_force))
        self.bus.publish(ev.StationStatus(run_id, self.clock.now(), devices={
            "table": {"connected": True, "simulated": True, "rate_dps": rate, "angle_deg": angle},
            "resonator": {"connected": True, "simulated": True, "drive": drive},
        }))

    def _wait(self, dt_s: float) -> None:
        """Advance by dt_s on the bench clock, honouring pause and abort."""
        while not self._resume.is_set():
            self._resume.wait(0.05)
        if self._abort.is_set():
            raise _Aborted
        self.clock.sleep(dt_s)

    def _run_decay(self, run_id: str, values: dict[str, Any]) -> str:
        duration_s, block_s = values["duration_s"], values["block_s"]
        self.tap.rate_dps = values["rate_dps"]
        t0 = self.clock.now()
        t_hist: list[float] = []
        e_hist: list[float] = []
        next_fit_s = 1.0
        n_blocks = max(1, int(round(duration_s / block_s)))
        for i in range(n_blocks):
            self._wait(block_s)
            block = self.world.last_block
            el = orbit_elements(block.q_meas[-1])
            t_hist.append(float(block.t_s[-1]))
            e_hist.append(float(el["E"]))
            elapsed = self.clock.now() - t0
            if elapsed >= next_fit_s or i == n_blocks - 1:
                next_fit_s += 1.0
                self._publish_status(run_id)
                self.bus.publish(ev.Progress(run_id, self.clock.now(), fraction=(i + 1) / n_blocks,
                                             message=f"{elapsed:.1f} of {duration_s:g} s"))
                if len(t_hist) >= 3:
                    tt, ee = np.array(t_hist), np.array(e_hist)
                    slope, icept = np.polyfit(tt, np.log(ee), 1)
                    t_fit = np.linspace(tt[0], tt[-1], 100)
                    self.bus.publish(ev.FitUpdate(run_id, self.clock.now(), name="E decay",
                                                  curves={"t_s": t_fit, "E": np.exp(icept + slope * t_fit)}))
        tau_s = -2.0 / slope if len(t_hist) >= 3 and slope < 0 else float("nan")
        true_tau = self.params.tau_s
        outcome = "PASS" if abs(tau_s - true_tau) < 0.05 * true_tau else "FAIL"
        self.bus.publish(ev.Measurement(run_id, self.clock.now(), name="tau", value=tau_s, unit="s",
                                        low=0.95 * true_tau, high=1.05 * true_tau, outcome=outcome))
        self.bus.publish(ev.Log(run_id, self.clock.now(), message=f"tau fitted {tau_s:.2f} s, true {true_tau:.2f} s"))
        return outcome

    def _run_sweep(self, run_id: str, values: dict[str, Any]) -> str:
        f0 = self.params.f0_hz
        freqs = f0 + np.linspace(-0.5, 0.5, values["points"]) * values["span_hz"]
        force = np.array([0.01, 0.0, 0.0, 0.0])
        self.world.set_force("drive", force)
        for i, f in enumerate(freqs):
            self.tap.ref_freq_hz = float(f)
            self.world.resonator.set_state(self.world.resonator.steady_state(force=force, ref_freq_hz=float(f)))
            self._wait(values["dwell_s"])
            q = self.world.last_block.q_meas.mean(axis=0)
            amp, phase_deg = float(np.hypot(q[0], q[1])), float(np.degrees(np.arctan2(-q[1], q[0])))
            self.bus.publish(ev.SampleBlock(run_id, self.clock.now(), stream="sweep",
                                            columns=("freq_hz", "amplitude", "phase_deg"),
                                            data=np.array([[f, amp, phase_deg]])))
            self.bus.publish(ev.Progress(run_id, self.clock.now(), fraction=(i + 1) / len(freqs),
                                         message=f"{f:.4f} Hz"))
        return "COMPLETE"
