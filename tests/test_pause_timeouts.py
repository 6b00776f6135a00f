"""A pause longer than a wait's timeout does not end the run when it resumes (issue 36's CI
failure: the window paused hrg-free-decay at 100x during its spin-up; the table reached its rate
while paused, and on the resume `wait_at_rate` found its 120 bench seconds gone and the run ended
ERROR).  The engine's clock counts the bench time paused; `ctx.wait_until` and the rate table's
waits leave it out of their timeouts, and a timeout that still comes says how long was paused.

The station of tests/test_record_pause.py lets 2 s of bench time pass while paused (as real time
would), deterministically."""

from __future__ import annotations

import pytest
from test_record_pause import PAUSED_S, PausingStation

from bench.engine import Procedure, Runner, step
from drivers.rate_table import ModbusRateTable, TableLimits
from simulators.rate_table import serve_modbus_table

LIMITS = TableLimits(max_rate_dps=500.0, max_accel_dps2=300.0)


class WaitsAcrossAPause(Procedure):
    """Pause, then wait for a condition that holds 0.5 s after the pause, with a 1 s timeout."""

    name = "pause-wait-test"
    runner: Runner | None = None
    waited: list[bool] = []

    @step("Wait")
    def wait(self, ctx):
        t0 = ctx.clock.now()
        type(self).runner.pause()  # held at the wait's first checkpoint for PAUSED_S of bench time
        ok = ctx.wait_until(lambda: ctx.clock.now() >= t0 + PAUSED_S + 0.5, timeout_s=1.0, poll_s=0.1)
        type(self).waited.append(ok)
        if not ok:
            raise TimeoutError("the condition did not hold within 1 s")


def test_wait_until_leaves_the_paused_time_out_of_its_timeout(tmp_path):
    station = PausingStation()
    runner = Runner(station, runs_dir=tmp_path)
    station.runner = WaitsAcrossAPause.runner = runner
    WaitsAcrossAPause.waited = []
    rec = runner.run(WaitsAcrossAPause)
    assert rec.outcome == "COMPLETE", rec.end_reason
    assert WaitsAcrossAPause.waited == [True]
    assert station.clock.paused_s == pytest.approx(PAUSED_S, abs=1e-9)


def test_wait_until_still_times_out_on_unpaused_time(tmp_path):
    station = PausingStation()
    runner = Runner(station, runs_dir=tmp_path)
    station.runner = WaitsAcrossAPause.runner = runner
    WaitsAcrossAPause.waited = []
    t0 = station.clock.now()
    ok = station.clock.wait_until(lambda: False, timeout_s=1.0, poll_s=0.1)  # no run, no pause: 1 s
    assert not ok and station.clock.now() - t0 == pytest.approx(1.0, abs=1e-6)


class SpinsAcrossAPause(Procedure):
    """Command 100 deg/s at 50 deg/s^2 (2 s of ramp), pause, wait at rate with a 1.5 s timeout."""

    name = "pause-spin-test"
    runner: Runner | None = None
    timeout_s = 1.5

    @step("Spin")
    def spin(self, ctx):
        table = ctx.devices.table
        table.enable()
        table.set_rate(100.0, accel_dps2=50.0)
        type(self).runner.pause()  # the ramp ends while paused
        table.wait_at_rate(0.05, 0.5, timeout_s=type(self).timeout_s)


def _spin(tmp_path, timeout_s: float):
    station = PausingStation()
    server = serve_modbus_table(station.world, framer="tcp")
    table = ModbusRateTable(server.host, server.port, limits=LIMITS, clock=station.clock, heartbeat_s=1e6)
    table.connect()
    station.devices = {"table": table}
    runner = Runner(station, runs_dir=tmp_path)
    station.runner = SpinsAcrossAPause.runner = runner
    SpinsAcrossAPause.timeout_s = timeout_s
    try:
        return runner.run(SpinsAcrossAPause)
    finally:
        table.close()
        server.stop()


def test_the_tables_wait_at_rate_leaves_the_paused_time_out(tmp_path):
    rec = _spin(tmp_path, timeout_s=1.5)  # 2 s of ramp: met only because the 2 s paused are not counted
    assert rec.outcome == "COMPLETE", rec.end_reason
    assert rec.safe_state


def test_a_timeout_after_a_pause_says_how_long_was_paused(tmp_path):
    rec = _spin(tmp_path, timeout_s=0.1)  # at rate after the pause, but not stable for 0.5 s within 0.1 s
    assert rec.outcome == "ERROR"
    assert "within 0.1 s (and 2.0 s paused, not counted)" in rec.end_reason, rec.end_reason
