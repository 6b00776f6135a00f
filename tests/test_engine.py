"""The engine: parameters checked before anything moves, steps, outcomes, abort at each step,
pause/resume, errors and lost links all end in a confirmed safe state in the engine's order."""

from __future__ import annotations

import threading

import pytest

from bench.clock import SimClock
from bench.engine import (
    GuardedClock,
    Limits,
    Measurement,
    Param,
    ParamError,
    Procedure,
    Runner,
    SafeStateReport,
    bring_to_safe_state,
    events,
    step,
)
from drivers.errors import LinkLostError
from simulators.physics.params import preset
from simulators.world import World


class FakeDevice:
    """Records safe_state calls into a shared list; answers `ok`."""

    def __init__(self, role: str, calls: list, ok: bool = True) -> None:
        self.role, self.calls, self.ok = role, calls, ok
        self.moved = False

    def move(self) -> None:
        self.moved = True

    def safe_state(self) -> bool:
        self.calls.append(self.role)
        return self.ok


class FakeStation:
    """The station protocol the runner needs, over a lockstep simulated world."""

    id = "fake"
    simulated = True
    seed = 0

    def __init__(self, ok: dict[str, bool] | None = None) -> None:
        self.world = World(preset("hrg"), seed=0)
        self.clock = GuardedClock(SimClock(self.world))
        self.calls: list[str] = []
        ok = ok or {}
        # deliberately listed out of safe order
        self.devices = {r: FakeDevice(r, self.calls, ok.get(r, True)) for r in ("frontend", "table", "fpga")}
        self.link_error: Exception | None = None

    def safe_state(self) -> SafeStateReport:
        return bring_to_safe_state(self.devices)

    def truth(self) -> dict[str, float]:
        return {"tau_s": 1.0}

    def describe(self) -> dict:
        return {"id": self.id}

    def check_links(self) -> None:
        if self.link_error is not None:
            raise self.link_error


class ThreeSteps(Procedure):
    """Three steps that wait on the bench clock and measure."""

    wait_s = Param(1.0, unit="s", low=0.0, high=100.0, doc="wait per step")
    value = Param(5.0, unit="deg", low=-10.0, high=10.0)
    mode = Param("a", choices=("a", "b"))
    n = Param(3, low=1, high=10)
    measurements = (Measurement("x_deg", "deg", "the parameter `value`, measured"),)

    @step("First")
    def first(self, ctx):
        ctx.devices.table.move()
        ctx.sleep(self.wait_s)

    @step
    def second(self, ctx):
        ctx.wait_until(lambda: False, timeout_s=self.wait_s)
        ctx.progress(0.5, "half")

    @step("Third")
    def third(self, ctx):
        ctx.sleep(self.wait_s)
        ctx.measure("x_deg", self.value, "deg", limits=Limits(-6, 6, -5.5, 5.5))


def test_params_defaults_conversion_and_names():
    p = ThreeSteps({"wait_s": "2.5", "n": "4", "mode": "b"})
    assert (p.wait_s, p.n, p.mode, p.value) == (2.5, 4, "b", 5.0)
    assert ThreeSteps.name == "three-steps"
    assert [s for s, _ in ThreeSteps.step_specs()] == ["first", "second", "third"]


@pytest.mark.parametrize(
    "given, text",
    [  # the wording of bench.validation: the value, and the limit or what was expected
        ({"wait_s": 101.0}, "wait_s=101 s is above the limit 100 s"),
        ({"wait_s": -1}, "wait_s=-1 s is below the limit 0 s"),
        ({"wait_s": "fast"}, "wait_s='fast' is not a number"),
        ({"wait_s": float("nan")}, "wait_s=nan is not a finite number"),
        ({"n": 1.5}, "n=1.5 is not an integer"),
        ({"mode": "c"}, "mode='c' is not one of a, b"),
        ({"nope": 1}, "nope: not a parameter of"),
    ],
)
def test_bad_params_are_rejected_before_anything_moves(given, text):
    station = FakeStation()
    runner = Runner(station)
    with pytest.raises(ParamError) as info:
        runner.run(ThreeSteps, given)
    assert str(info.value).startswith(text), str(info.value)
    assert not station.devices["table"].moved and station.calls == []


def test_normal_run_orders_events_and_safe_state():
    station = FakeStation()
    runner = Runner(station)
    seen: list[events.Event] = []
    runner.bus.subscribe(seen.append)
    rec = runner.run(ThreeSteps, {"wait_s": 0.5})
    assert rec.outcome == "PASS" and rec.end_reason == "completed" and rec.safe_state
    assert station.calls == ["fpga", "table", "frontend"]
    # three waits of 0.5 s of virtual time
    assert rec.simulated_s == pytest.approx(1.5, abs=2e-3)
    kinds = [type(e).__name__ for e in seen]
    assert kinds[0] == "RunStarted" and kinds[-1] == "RunFinished"
    assert kinds.count("StepStarted") == 3 and "Progress" in kinds and "Measurement" in kinds
    js = rec.as_json()
    assert js["measurements"]["x_deg"] == {
        "value": 5.0,
        "unit": "deg",
        "ci95": None,
        "limits": [-6.0, 6.0],
        "marginal": [-5.5, 5.5],  # the marginal band, no longer dropped
        "outcome": "PASS",
    }
    assert js["truth"] == {"tau_s": 1.0}


@pytest.mark.parametrize("value, outcome", [(5.0, "PASS"), (5.8, "MARGINAL"), (-5.9, "MARGINAL"), (6.5, "FAIL")])
def test_measurement_outcomes(value, outcome):
    rec = Runner(FakeStation()).run(ThreeSteps, {"wait_s": 0.0, "value": value})
    assert rec.outcome == outcome and rec.measurements[0].outcome == outcome


@pytest.mark.parametrize("abort_at", ["first", "second", "third"])
def test_abort_at_each_step_reaches_safe_state(abort_at):
    station = FakeStation()
    runner = Runner(station)

    def on_event(e):
        if isinstance(e, events.StepStarted) and e.name == abort_at:
            runner.abort("operator")

    runner.bus.subscribe(on_event)
    seen: list[events.Event] = []
    runner.bus.subscribe(seen.append)
    rec = runner.run(ThreeSteps, {"wait_s": 1.0})
    assert rec.outcome == "ABORTED" and rec.end_reason == "aborted: operator"
    assert rec.failed_step == abort_at
    assert rec.safe_state and station.calls == ["fpga", "table", "frontend"]
    assert [(r.name, r.outcome) for r in rec.measurements] == [("x_deg", "NOT_MEASURED")]  # declared, not reached
    fin = [e for e in seen if isinstance(e, events.StepFinished)]
    assert fin[-1].name == abort_at and fin[-1].status == "aborted"
    assert isinstance(seen[-1], events.RunFinished) and seen[-1].safe_state


def test_error_in_step_is_error_with_step_name():
    class Broken(ThreeSteps):
        @step
        def fourth(self, ctx):
            raise ValueError("no fringe found")

    station = FakeStation()
    rec = Runner(station).run(Broken, {"wait_s": 0.0})
    assert rec.outcome == "ERROR" and "fourth" in rec.end_reason and "no fringe found" in rec.end_reason
    assert rec.safe_state and station.calls == ["fpga", "table", "frontend"]
    assert [m.name for m in rec.measurements] == ["x_deg"]  # what was measured stays


def test_lost_link_seen_at_a_checkpoint():
    station = FakeStation()
    runner = Runner(station)
    runner.bus.subscribe(
        lambda e: setattr(station, "link_error", LinkLostError("fpga: no frame for 1 s"))
        if isinstance(e, events.StepStarted) and e.name == "second"
        else None
    )
    rec = runner.run(ThreeSteps, {"wait_s": 1.0})
    assert rec.outcome == "ERROR" and rec.end_reason.startswith("link lost: fpga")
    station.link_error = None
    assert rec.safe_state


def test_unconfirmed_safe_state_makes_the_run_an_error_but_visits_every_device():
    station = FakeStation(ok={"fpga": False})
    rec = Runner(station).run(ThreeSteps, {"wait_s": 0.0})
    assert rec.outcome == "ERROR" and not rec.safe_state
    assert station.calls == ["fpga", "table", "frontend"]
    assert rec.safe_detail["devices"] == {"fpga": False, "table": True, "frontend": True}


def test_pause_holds_virtual_time_and_resume_continues():
    station = FakeStation()
    runner = Runner(station)
    paused_at: list[float] = []
    resumed = threading.Event()

    def on_event(e):
        if isinstance(e, events.StepStarted) and e.name == "second":
            runner.pause()
            paused_at.append(station.world.t_s)

            def later():
                # while paused the engine thread is held: virtual time must not move
                assert resumed.wait(0) is False
                paused_at.append(station.world.t_s)
                resumed.set()
                runner.resume()

            threading.Timer(0.3, later).start()

    runner.bus.subscribe(on_event)
    rec = runner.run(ThreeSteps, {"wait_s": 1.0})
    assert resumed.is_set() and paused_at[0] == paused_at[1]
    assert rec.outcome == "PASS" and rec.wall_s >= 0.3


def test_missing_device_role_is_refused_before_anything_moves():
    class NeedsFrontEndAndLaser(ThreeSteps):
        requires = ("frontend", "laser")

    station = FakeStation()
    with pytest.raises(ValueError, match=r"needs device role\(s\) \['laser'\]; station 'fake' has"):
        Runner(station).run(NeedsFrontEndAndLaser)
    assert station.calls == [] and not station.devices["table"].moved


def test_abort_requested_before_the_run_starts_still_aborts():
    station = FakeStation()
    runner = Runner(station)
    runner.abort("SIGINT")  # Ctrl-C while the station was opening
    rec = runner.run(ThreeSteps)
    assert rec.outcome == "ABORTED" and rec.end_reason == "aborted: SIGINT" and rec.safe_state
    assert not station.devices["table"].moved
    assert Runner.run(runner, ThreeSteps, {"wait_s": 0.0}).outcome == "PASS"  # the abort does not leak


def test_a_failing_recorder_makes_the_run_an_error_and_the_record_is_still_written(tmp_path, monkeypatch):
    """Disk full, h5py error...: the run must not end COMPLETE with raw data missing."""
    from bench.composition.sim_station import SimStation
    from bench.engine import Runner
    from bench.recorder import Recorder
    from procedures.examples.table_spin import TableSpin

    real = Recorder.on_event

    def flaky(self, event):
        if getattr(event, "stream", "") == "hold":
            raise OSError("disk full")
        return real(self, event)

    monkeypatch.setattr(Recorder, "on_event", flaky)
    station = SimStation("sim-hrg", seed=0).open()
    try:
        rec = Runner(station, runs_dir=tmp_path).run(TableSpin, {"hold_s": 0.5})
    finally:
        station.close()
    assert rec.outcome == "ERROR" and "disk full" in rec.end_reason
    assert rec.safe_state
