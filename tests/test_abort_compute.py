"""Abort in a long computation (issue 13 item 13): a step's estimator runs where the engine can
end it (`ctx.compute`), so an abort is honoured within 1 s wall with the safe state confirmed."""

from __future__ import annotations

import math
import threading
import time

import pytest

from bench.composition.sim_station import SimStation
from bench.engine import Procedure, Runner, step


class SpinThenThink(Procedure):
    """Spin the table, then a computation far longer than anyone would wait."""

    requires = ("table",)
    think = "worker"

    @step("Spin")
    def spin(self, ctx):
        ctx.devices.table.enable()
        ctx.devices.table.set_rate(100.0)
        ctx.devices.table.wait_at_rate(tolerance_dps=0.1, stable_for_s=0.2, timeout_s=60.0)

    @step("Analyse")
    def analyse(self, ctx):
        self.started = time.monotonic()
        if self.think == "worker":
            ctx.compute(time.sleep, 600.0)  # a builtin: the worker process imports it by name
        else:
            ctx.compute(lambda: time.sleep(600.0))  # not importable: a thread, still abortable


class Failing(Procedure):
    """An estimator error in the worker comes back as itself."""

    @step("Analyse")
    def analyse(self, ctx):
        ctx.compute(math.sqrt, -1.0)


@pytest.fixture
def station():
    st = SimStation("sim-hrg").open()
    yield st
    st.close()


@pytest.mark.serial  # an abort answered within 1 s of wall time: run alone
@pytest.mark.parametrize("think", ["worker", "thread"])
def test_abort_during_a_long_analysis_returns_within_a_second_with_the_safe_state(station, think):
    runner = Runner(station)
    proc = SpinThenThink()
    proc.think = think
    done: dict = {}

    def abort_when_analysing():
        while not hasattr(proc, "started"):
            time.sleep(0.01)
        time.sleep(1.0)  # well inside the computation (the worker has started)
        done["abort_at"] = time.monotonic()
        runner.abort("operator")

    th = threading.Thread(target=abort_when_analysing, daemon=True)
    th.start()
    rec = runner.run(proc)
    returned = time.monotonic()
    assert rec.outcome == "ABORTED" and rec.end_reason == "aborted: operator"
    assert rec.failed_step == "analyse"
    assert rec.safe_state and rec.safe_detail["devices"] == {"table": True, "frontend": True, "fpga": True}
    assert returned - done["abort_at"] < 1.0
    mech = station.handles["table"].mechanics
    assert not mech.enabled and abs(mech.rate_dps) < 0.1


def test_an_error_in_the_worker_fails_the_step_with_its_own_name(station):
    rec = Runner(station).run(Failing())
    assert rec.outcome == "ERROR" and rec.end_reason == "ValueError in step 'analyse': math domain error"
    assert rec.safe_state


def test_compute_returns_the_value_of_the_function():
    from bench.engine.compute import run_in_worker

    assert run_in_worker(math.hypot, (3.0, 4.0), {}, lambda: None) == 5.0


def test_abort_takes_no_lock_a_signal_handler_could_find_held():
    """SIGTERM's handler calls abort() in the main thread, which may be inside the checkpoint's
    Event.wait holding that Event's lock at that moment: abort must not wait for it (a hang in
    1 of 40 signalled runs of benchmarks/reliability_faults.py)."""
    runner = Runner(SimStation("sim-hrg"))  # not opened: only the control flags are used
    returned = threading.Event()

    def handler_inside_wait():
        with runner._running._cond:  # what Event.wait holds between its bytecodes
            runner.abort("SIGTERM")
            returned.set()

    th = threading.Thread(target=handler_inside_wait, daemon=True)
    th.start()
    assert returned.wait(2.0)
    assert runner._abort_reason == "SIGTERM"


def test_abort_while_paused_is_honoured(station):
    runner = Runner(station)
    proc = SpinThenThink()

    def pause_then_abort():
        while not hasattr(proc, "started"):
            time.sleep(0.01)
        runner.pause()
        time.sleep(0.3)
        runner.abort("operator")

    threading.Thread(target=pause_then_abort, daemon=True).start()
    t0 = time.monotonic()
    rec = runner.run(proc)
    assert rec.outcome == "ABORTED" and rec.safe_state and time.monotonic() - t0 < 30.0


def test_a_worker_runs_blas_on_one_thread():
    """A freshly forked worker's threaded BLAS cost more to start than the estimators' small
    matrices gain (a 900 s decay fit: 0.2-0.5 s against 0.09 s on one thread)."""
    from threadpoolctl import threadpool_info

    from bench.engine.compute import run_in_worker

    blas = [lib for lib in run_in_worker(threadpool_info, (), {}, lambda: None) if lib["user_api"] == "blas"]
    assert blas and all(lib["num_threads"] == 1 for lib in blas), blas
