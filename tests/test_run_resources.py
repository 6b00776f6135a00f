"""Run-scoped resources: whatever a procedure acquired through its run context (stream
subscriptions, deferred teardowns) is released by the runner when the run ends, whichever step
failed, before the safe state; nothing stays subscribed, no tap keeps rows, no thread is left.

Every registered procedure runs (short parameters) once per step with a fault injected in that
step: at its first progress report while it records, or else at its end (after it acquired
whatever it acquires).  One station per procedure stays open across the runs, as in the window."""

from __future__ import annotations

import threading

import pytest

from bench.engine import Runner
from bench.engine.context import RunContext
from bench.engine.measurement import ERROR
from procedures import all_procedures

#: short parameters, and the station, of each procedure
SHORT = {
    "hrg-damping": ("sim-hrg", {"rate_dps": 20.0, "record_s": 2.0, "stream_hz": 200.0, "verify_rate_dps": 4.0,
                                "verify_s": 2.0, "verify_settle_s": 0.5, "drift_block_s": 0.5}),
    "hrg-free-decay": ("sim-hrg", {"rate_dps": 20.0, "record_s": 2.0}),
    "mems-sweep": ("sim-mems", {"n_points": 5}),
    "table-spin": ("sim-hrg", {"hold_s": 0.5}),
    "cvg-allan": ("sim-hrg-wa", {"record_s": 60.0, "settle_s": 1.0}),
    "cvg-scale-factor": ("sim-hrg", {"max_rate_dps": 10.0, "steps": 2, "average_s": 0.5, "settle_s": 0.2,
                                     "whole_turns": False}),
    "hrg-selfcal": ("sim-hrg-selfcal", {"cycles": 2, "precession_dps": 2.0, "settle_s": 1.0, "bin_s": 1.0,
                                        "fm_force_hz": 0.0,
                                        "smooth_s": 10.0}),
    "cvg-bias": ("sim-hrg-ftr", {"record_s": 2.0, "turn_ons": 2, "quench_s": 1.0, "settle_s": 0.5, "batches": 2}),
    "thermal-ramp": ("sim-hrg-thermal-quick", {"t_low_degc": 24.0, "t_high_degc": 26.0, "cycle_degc_per_min": 5.0,
                                               "segment_s": 5.0, "tail_s": 5.0, "settle_window_s": 10.0,
                                               "settle_ppm_per_min": 1.0, "max_order": 1, "verify_points": 0,
                                               "record_s": 2.0}),
    "thermal-soak": ("sim-hrg-thermal-quick", {"t_low_degc": 24.0, "t_high_degc": 26.0, "points": 3,
                                               "settle_window_s": 10.0, "settle_ppm_per_min": 1.0,
                                               "settle_windows": 1, "record_s": 2.0, "batches": 2}),
}


class InjectedFault(RuntimeError):
    """The fault a test puts into a step."""


def _subscribed(station) -> dict[str, int]:
    """Stream subscribers per device (the station's own recorder feed is gone between runs)."""
    return {role: len(getattr(dev, "_subscribers", ())) for role, dev in station.devices.items()}


def _taps_on(proc) -> list[str]:
    return [name for name, value in vars(proc).items() if getattr(value, "on", False) is True]


def test_every_procedure_is_covered():
    assert set(all_procedures()) <= set(SHORT), "give the new procedure short parameters here"


@pytest.mark.parametrize("name", sorted(SHORT))
def test_a_fault_in_any_step_leaves_nothing_subscribed_and_no_thread(name, tmp_path, monkeypatch):
    from bench.composition.sim_station import SimStation

    cls = all_procedures()[name]
    station_name, params = SHORT[name]
    armed = {"step": None}
    progress = RunContext.progress

    def faulty_progress(self, fraction, message=""):
        if armed["step"] is not None:
            step, armed["step"] = armed["step"], None
            raise InjectedFault(f"fault injected in step {step!r} (while it records)")
        return progress(self, fraction, message)

    monkeypatch.setattr(RunContext, "progress", faulty_progress)
    station = SimStation(station_name, seed=0).open()
    try:
        before_subs = _subscribed(station)
        before_threads = set(threading.enumerate())
        for step, _title in cls.step_specs():
            proc = cls(params)
            original = getattr(proc, step)

            def faulty(ctx, step=step, original=original):
                armed["step"] = step
                original(ctx)
                if armed["step"] is not None:  # no progress report in it: the fault comes at its end
                    armed["step"] = None
                    raise InjectedFault(f"fault injected in step {step!r} (at its end)")

            setattr(proc, step, faulty)
            record = Runner(station, runs_dir=tmp_path / "runs").run(proc)
            assert record.outcome == ERROR and record.failed_step == step, (step, record.end_reason)
            assert "InjectedFault" in record.end_reason
            assert record.safe_state, (step, record.safe_detail)
            assert _subscribed(station) == before_subs, f"{name}: still subscribed after a fault in {step!r}"
            assert _taps_on(proc) == [], f"{name}: a tap is left on after a fault in {step!r}"
            left = [t.name for t in set(threading.enumerate()) - before_threads if t.is_alive()]
            assert left == [], f"{name}: threads left after a fault in {step!r}: {left}"
    finally:
        station.close()


def test_teardowns_run_last_first_and_a_failing_or_hanging_one_does_not_stop_the_others():
    from bench.engine import events as ev
    from bench.engine.context import GuardedClock

    class Clock:
        def now(self) -> float:
            return 0.0

    ctx = RunContext(run_id="r", params={}, devices={}, clock=GuardedClock(Clock()), bus=ev.EventBus())
    done: list[str] = []
    release = threading.Event()

    def fails() -> None:
        raise OSError("port gone")

    ctx.defer(lambda: done.append("first"), "first")
    ctx.defer(fails, "fails")
    ctx.defer(lambda: release.wait(5.0), "hangs")
    ctx.defer(lambda: done.append("last"), "last")
    failures = ctx.close_resources(timeout_s=0.2)
    release.set()
    assert done == ["last", "first"]
    assert failures == ["hangs: still running after 0.2 s", "fails: OSError: port gone"]
    assert ctx.close_resources() == []  # each teardown runs once


def test_no_procedure_subscribes_to_a_device_itself():
    """Subscriptions go through `ctx.subscribe` (released by the runner), never `device.subscribe`."""
    import inspect
    import re

    for name, cls in all_procedures().items():
        for klass in cls.__mro__:
            if klass.__module__.startswith("procedures"):
                src = inspect.getsource(klass)
                calls = re.findall(r"([\w.\]\[\"']+)\.subscribe\(", src)
                assert all(c == "ctx" for c in calls), f"{name} ({klass.__name__}) calls {calls} .subscribe itself"
