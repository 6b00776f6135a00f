"""Records to an absolute deadline, and a pause inside one (issue 31 items 1 and 2).

A pause is an event in the log and in the raw file; inside a record it either excludes the paused
span (and the record runs on by as much) or restarts the record, as the procedure declares.  The
bench time that passes while paused (a real-time station) is simulated deterministically: the
station's link check, which the engine calls while it holds, advances the world by 0.5 s and
resumes the run after the fourth call (2 s of bench time paused), so no test depends on timing."""

from __future__ import annotations

import numpy as np
import pytest

from bench.clock import SimClock
from bench.engine import GuardedClock, Procedure, RecordSpan, Runner, bring_to_safe_state, events, step
from bench.engine.recording import in_spans, recorded_length_s, recorded_text
from simulators.physics.params import preset
from simulators.world import World

RECORD_S = 3.0
PAUSED_S = 2.0


class PausingStation:
    """A lockstep world; while the runner is paused its link check lets 0.5 s of bench time pass
    (as real time would) and resumes after PAUSED_S."""

    id = "pausing"
    simulated = True
    seed = 0

    def __init__(self) -> None:
        self.world = World(preset("hrg"), seed=0)
        self.clock = GuardedClock(SimClock(self.world))
        self.devices: dict = {}
        self.runner: Runner | None = None
        self._held_s = 0.0

    def check_links(self) -> None:
        runner = self.runner
        if runner is not None and runner.paused:
            self.world.advance(0.5)
            self._held_s += 0.5
            if self._held_s >= PAUSED_S - 1e-9:
                self._held_s = 0.0
                runner.resume()

    def safe_state(self):
        return bring_to_safe_state(self.devices)

    def truth(self) -> dict:
        return {}

    def describe(self) -> dict:
        return {"id": self.id}


class Records(Procedure):
    """Record RECORD_S seconds (the span kept for the test)."""

    name = "records-test"
    spans: list[RecordSpan] = []

    @step("Record")
    def record(self, ctx):
        ctx.sleep(0.5)
        type(self).spans.append(ctx.record_for(RECORD_S, "test record", progress_every_s=1.0))


class RecordsRestart(Records):
    """Record, restarting after a pause."""

    name = "records-restart-test"
    pause_in_record = "restart"


def _run(proc: type[Records], tmp_path, pause: bool):
    station = PausingStation()
    runner = Runner(station, runs_dir=tmp_path)
    station.runner = runner
    proc.spans = []
    seen: list = []

    def on_event(e):
        seen.append(e)
        if pause and isinstance(e, events.Progress) and e.message.startswith("test record: 1 ") \
                and not any(isinstance(x, events.Paused) for x in seen):
            runner.pause()  # one second into the record, once

    runner.bus.subscribe(on_event)
    rec = runner.run(proc)
    assert rec.outcome == "COMPLETE", rec.end_reason
    return rec, proc.spans[-1], seen


def test_a_record_without_pause_ends_at_the_deadline(tmp_path):
    rec, span, _ = _run(Records, tmp_path, pause=False)
    assert span.t_end_s - span.t_start_s == pytest.approx(RECORD_S, abs=1e-9)
    assert span.excluded == () and span.restarts == 0
    assert rec.simulated_s == pytest.approx(0.5 + RECORD_S, abs=1e-3)


def test_pause_is_an_event_in_the_log_and_the_raw_file(tmp_path):
    from bench.recorder import RunData

    rec, span, seen = _run(Records, tmp_path, pause=True)
    paused = [e for e in seen if isinstance(e, events.Paused)]
    resumed = [e for e in seen if isinstance(e, events.Resumed)]
    assert len(paused) == 1 and len(resumed) == 1
    assert resumed[0].t_sim_s - paused[0].t_sim_s == pytest.approx(PAUSED_S, abs=1e-6)
    assert resumed[0].paused_from_s == paused[0].t_sim_s
    with RunData(rec.raw_file) as data:
        levels = [r["level"] for r in data.log()]
        assert levels.count("PAUSE") == 2
        assert data.pauses() == [(pytest.approx(paused[0].t_sim_s), pytest.approx(resumed[0].t_sim_s))]


def test_a_pause_inside_an_excluding_record_is_cut_out_and_said(tmp_path):
    """pause_in_record = "exclude": the paused span is excluded, the record runs on by as much,
    and the warning in the log names the span."""
    _, span, seen = _run(Records, tmp_path, pause=True)
    a, b = span.excluded[0]
    assert len(span.excluded) == 1 and b - a == pytest.approx(PAUSED_S, abs=1e-6)
    assert span.t_end_s - span.t_start_s == pytest.approx(RECORD_S + PAUSED_S, abs=1e-6)
    t = np.arange(span.t_start_s, span.t_end_s + 1e-9, 1e-3)
    kept = t[span.keep(t)]
    assert not in_spans(kept, span.excluded).any()
    assert len(kept) * 1e-3 == pytest.approx(RECORD_S, abs=2e-3)  # record_s of unpaused data
    warnings = [e.message for e in seen if isinstance(e, events.Log) and e.level == "WARNING"]
    assert any("excluded" in w for w in warnings)
    assert "paused inside the record excluded" in recorded_text("test record", kept, span)


def test_a_pause_inside_a_restarting_record_starts_it_again(tmp_path):
    """pause_in_record = "restart": the record starts again at the resume and holds record_s."""
    _, span, seen = _run(RecordsRestart, tmp_path, pause=True)
    resumed = [e for e in seen if isinstance(e, events.Resumed)][0]
    assert span.restarts == 1 and span.excluded == ()
    assert span.t_start_s == pytest.approx(resumed.t_sim_s, abs=1e-6)
    assert span.t_end_s - span.t_start_s == pytest.approx(RECORD_S, abs=1e-9)
    warnings = [e.message for e in seen if isinstance(e, events.Log) and e.level == "WARNING"]
    assert any("restarts" in w for w in warnings)


def test_recorded_length_from_the_samples():
    t = 10.0 + 0.01 * np.arange(1, 501)
    length, n, period = recorded_length_s(t)
    assert (n, length) == (500, pytest.approx(5.0)) and period == pytest.approx(0.01)


def _paused_sim_run(tmp_path, proc, trigger: str):
    """proc on sim-hrg, paused once at the Progress message starting with `trigger` for PAUSED_S
    of bench time (passing as at a real-time speed, but deterministically)."""
    from bench.composition.sim_station import SimStation

    station = SimStation("sim-hrg", seed=4).open()
    try:
        runner = Runner(station, runs_dir=tmp_path)
        held = {"s": 0.0}
        check = station.check_links

        def check_links() -> None:  # while paused, bench time passes (real time would)
            if runner.paused:
                station.world.advance(0.5)
                held["s"] += 0.5
                if held["s"] >= PAUSED_S - 1e-9:
                    runner.resume()
            check()

        station.check_links = check_links

        def on_event(e):
            if isinstance(e, events.Progress) and e.message.startswith(trigger) and held["s"] == 0.0:
                runner.pause()

        runner.bus.subscribe(on_event)
        return runner.run(proc)
    finally:
        station.close()


def test_hrg_free_decay_restarts_its_decay_after_a_pause(tmp_path):
    """hrg-free-decay declares "restart": its decay window starts at the resume and holds record_s."""
    from bench.recorder import RunData
    from procedures.hrg_free_decay import HrgFreeDecay

    proc = HrgFreeDecay({"rate_dps": 20.0, "record_s": 12.0, "method": "equation-error"})
    rec = _paused_sim_run(tmp_path, proc, "free decay: 6 ")
    assert rec.outcome == "COMPLETE", rec.end_reason
    with RunData(rec.raw_file) as data:
        (a, b), = data.pauses()
        win = data.table("decay_window")
        assert win["t_start_s"][-1] == pytest.approx(b)
        assert win["t_end_s"][-1] - win["t_start_s"][-1] == pytest.approx(12.0, abs=1e-9)
        assert any("restarts" in r["msg"] and r["level"] == "WARNING" for r in data.log())


def test_hrg_damping_excludes_a_pause_from_its_decay_and_its_refit(tmp_path):
    """End to end on sim-hrg: a pause 6 s into a 12 s decay (2 s of bench time passing, as at a
    real-time speed) is cut out of the decay the fit takes, the record runs on by 2 s, the log and
    the raw file say so, and `analysis` of the raw file leaves the same samples out."""
    from bench.recorder import RunData
    from procedures.hrg_damping import TAP, HrgDamping

    proc = HrgDamping({"rate_dps": 20.0, "record_s": 12.0, "stream_hz": 200.0, "compensate": False})
    rec = _paused_sim_run(tmp_path, proc, "free decay: 6 ")
    assert rec.outcome == "COMPLETE", rec.end_reason
    t = TAP.column(proc._decay, "t_s")
    length, n, period = recorded_length_s(t)
    assert abs(length - 12.0) <= period  # record_s of data, the paused span excluded
    gap = np.diff(t).max()
    assert gap == pytest.approx(PAUSED_S + period, abs=2 * period)
    with RunData(rec.raw_file) as data:
        (a, b), = data.pauses()
        assert b - a == pytest.approx(PAUSED_S, abs=1e-6) and not in_spans(t, [(a, b)]).any()
        assert any("excluded" in r["msg"] and r["level"] == "WARNING" for r in data.log())
        assert any("paused inside the record excluded" in r["msg"] for r in data.log())
        live = {r.name: r.value for r in rec.measurements if r.measured}
        refit = {r.name: r.value for r in proc.analysis(data)}
        assert any("inside a pause left out" in note for note in data.notes)
    assert refit["tau_s"] == pytest.approx(live["tau_s"], rel=1e-9)
