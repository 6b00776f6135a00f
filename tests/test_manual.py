"""Manual control as a session the engine owns like a run, on the simulated station: each action
checked with the procedures' limits (a rate beyond the table's limit is refused, naming it), every
action in the session's record (store row, raw file), a fault during the session brings the table
to rest and cuts the drive (checked against the simulator's own state), and a run and a session
exclude each other with one message saying why."""

from __future__ import annotations

import threading

import h5py
import numpy as np
import pytest

from bench.engine import Runner
from bench.engine.manual import ACTION_CODES, ACTIONS_STREAM, ManualSession
from bench.engine.measurement import ABORTED, COMPLETE, ERROR
from bench.results import ResultsStore
from bench.validation import ValidationError


@pytest.fixture
def runner(sim_station, tmp_path):
    store = ResultsStore(tmp_path / "results.sqlite")
    yield Runner(sim_station, runs_dir=tmp_path / "runs", store=store)
    store.close()


def _start(runner, station):
    session = ManualSession(station)
    out: dict = {}
    thread = threading.Thread(target=lambda: out.setdefault("rec", runner.run(session.procedure())), daemon=True)
    thread.start()
    for _ in range(500):
        if session.state.active:
            break
        thread.join(0.02)
    assert session.state.active
    return session, thread, out


def _wait_for(cond, thread, timeout_s=30.0):
    for _ in range(int(timeout_s / 0.02)):
        if cond():
            return True
        thread.join(0.02)
    return cond()


def test_a_rate_beyond_the_table_limit_is_refused_naming_the_limit(sim_station, runner):
    session, thread, out = _start(runner, sim_station)
    try:
        with pytest.raises(ValidationError) as err:
            session.submit("table_rate", 1500.0)
        assert "rate_dps=1500 deg/s" in str(err.value) and "limit 1000 deg/s" in str(err.value)
        with pytest.raises(ValidationError, match=r"agc_setpoint=50 is above the limit 10"):
            session.submit("agc_setpoint", "50")
        with pytest.raises(ValidationError, match=r"rate_dps='fast' is not a number"):
            session.submit("table_rate", "fast")
        assert session.submit("table_rate", 100.0).wait()
        assert _wait_for(lambda: abs(sim_station.world.case_rate_dps - 100.0) < 0.5, thread)
        assert session.submit("table_stop").wait()
    finally:
        session.end()
        thread.join(60)
    rec = out["rec"]
    assert rec.procedure == "manual" and rec.outcome == COMPLETE and rec.safe_state
    assert abs(sim_station.world.case_rate_dps) < 0.1
    row = runner.store.get_run(rec.run_id)
    assert row["procedure"] == "manual" and row["outcome"] == COMPLETE
    with h5py.File(rec.raw_file, "r") as f:  # the raw file holds every action
        acts = np.asarray(f["streams/manual_actions"]) if "streams/manual_actions" in f else None
        assert acts is not None, list(f)
        codes = acts[:, ACTIONS_STREAM.index("action")].astype(int).tolist()
        # the three refused values are there too (accepted 0), before the rate that was done
        kinds = ("start", "table_rate", "agc_setpoint", "table_rate", "table_rate", "table_stop")
        assert codes == [ACTION_CODES[k] for k in kinds]
        assert acts[:, ACTIONS_STREAM.index("accepted")].astype(int).tolist() == [1, 0, 0, 0, 1, 1]
        assert acts[1, ACTIONS_STREAM.index("rate_cmd_dps")] == 0.0  # refused: nothing commanded
        assert acts[4, ACTIONS_STREAM.index("rate_cmd_dps")] == 100.0
        assert "fpga" in f["streams"]  # the stream the session started


@pytest.mark.parametrize("fault", ["table-fault", "link-drop"])
def test_a_fault_during_a_session_brings_the_table_to_rest_and_cuts_the_drive(sim_station, runner, fault):
    world = sim_station.world
    session, thread, out = _start(runner, sim_station)
    try:
        assert session.submit("drive_on").wait()
        assert session.submit("table_rate", 200.0).wait()
        assert _wait_for(lambda: abs(world.case_rate_dps - 200.0) < 0.5, thread)
        with world.lock:
            assert np.any(world.total_force)  # the drive is on
        sim_station.inject(fault)
        thread.join(60)
    finally:
        session.end()
        thread.join(60)
    rec = out["rec"]
    assert rec.outcome == ERROR and rec.safe_state, rec.end_reason
    assert ("trip" in rec.end_reason) if fault == "table-fault" else ("link lost" in rec.end_reason)
    assert abs(world.case_rate_dps) < 0.1  # the simulator's own state: at rest, drive cut
    with world.lock:
        assert not np.any(world.total_force)
    assert not session.state.active
    with pytest.raises(ValidationError, match="no manual control session is active"):
        session.submit("table_stop")


def test_a_run_cannot_start_while_a_session_holds_the_station(sim_station, runner):
    from procedures.examples.table_spin import TableSpin

    session, thread, out = _start(runner, sim_station)
    try:
        with pytest.raises(RuntimeError, match=r"manual control holds station 'sim-hrg'.*before starting a run"):
            runner.run(TableSpin, {"rate_dps": 10.0})
    finally:
        runner.abort("safe state button")
        thread.join(60)
    assert out["rec"].outcome == ABORTED and out["rec"].safe_state


def test_stream_stop_and_start_are_done_and_recorded(sim_station, runner):
    link = sim_station.devices["fpga"]
    session, thread, out = _start(runner, sim_station)
    try:
        assert session.submit("stream_stop").wait()
        assert not link._streaming and session.state.stream_on is False
        frames = link.stats.frames
        assert session.submit("table_rate", 10.0).wait()  # time passes, link checks go on, no frames
        assert _wait_for(lambda: abs(sim_station.world.case_rate_dps - 10.0) < 0.5, thread)
        assert link.stats.frames == frames
        assert session.submit("stream_start").wait()
        assert _wait_for(lambda: link.stats.frames > frames + 100, thread)
    finally:
        session.end()
        thread.join(60)
    rec = out["rec"]
    assert rec.outcome == COMPLETE and rec.safe_state, rec.end_reason
    with h5py.File(rec.raw_file, "r") as f:
        acts = np.asarray(f["streams/manual_actions"])
        on = acts[:, ACTIONS_STREAM.index("stream_on")].astype(int).tolist()
        assert on == [1, 0, 0, 1]
        log = "\n".join(x.decode() if isinstance(x, bytes) else str(x) for x in np.asarray(f["log"]).ravel())
        assert "manual: stream_stop" in log and "manual: table_rate 10" in log
