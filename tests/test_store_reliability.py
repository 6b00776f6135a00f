"""The results store when things go wrong: a run's row exists from its start (RUNNING, kept fresh
by a heartbeat) and becomes INTERRUPTED once its process is gone; a store that cannot be written
loses no record (the spool keeps it until `sync`); processes creating a fresh store at once all
succeed; a PostgreSQL URL without its driver names the extra to install.  SQLite and PostgreSQL."""

from __future__ import annotations

import datetime as _dt
import os
import subprocess
import sys
import time

import pytest

from bench.engine import Result, RunRecord
from bench.engine.measurement import INTERRUPTED, RUNNING
from bench.results import ResultsStore, StoreError
from bench.results.liveness import age_s, host_name, new_token
from bench.results.spool import Spool

DOWN_PG = "postgresql+psycopg://postgres@127.0.0.1:1/nowhere"  # nothing listens on port 1


def _record(run_id: str, outcome: str = "PASS") -> RunRecord:
    return RunRecord(
        run_id=run_id,
        procedure="table-spin",
        params={"rate_dps": 100.0},
        station_id="sim-hrg",
        simulated=True,
        outcome=outcome,
        end_reason="completed",
        safe_state=True,
        measurements=[Result("rate_dps", 100.01, "deg/s", limits=(99.5, 100.5))],
        truth={"rate_dps": 100.0},
        started_at=_dt.datetime.now(_dt.UTC).isoformat(),
        raw_file=f"/data/runs/{run_id}.h5",
        seed=3_000_000_000,
    )


OTHER_BOOT = "0b0e0f00-0000-4000-8000-000000000000"  # another PC's (or an earlier boot's) boot id


def _running_doc(run_id: str, *, host: str, pid: int, beat_age_s: float, here: bool | None = None) -> dict:
    """A RUNNING document; its token of this boot when `here` (default: host is this host's name)."""
    here = host == host_name() if here is None else here
    token = new_token(pid) if here else f"{OTHER_BOOT}/{pid}/1234/abcdef012345"
    doc = ResultsStore.record_doc(_record(run_id), outcome=RUNNING, token=token)
    beat = _dt.datetime.now(_dt.UTC) - _dt.timedelta(seconds=beat_age_s)
    doc["run"].update(host=host, pid=pid, heartbeat_at=beat.isoformat())
    return doc


def _dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def test_run_row_is_running_with_a_fresh_heartbeat_then_finished(store_url):
    store = ResultsStore(store_url)
    store.heartbeat_s = 0.05
    rec = _record("20260101-000000-aaaaaa")
    assert store.begin_run(rec) == []
    row = store.get_run("20260101-000000-aaaaaa")
    assert (row["outcome"], row["host"], row["pid"]) == (RUNNING, host_name(), os.getpid())
    assert row["raw_file"] == rec.raw_file and row["measurements"] == []
    first = row["heartbeat_at"]
    deadline = time.monotonic() + 5
    while store.get_run(rec.run_id)["heartbeat_at"] == first and time.monotonic() < deadline:
        time.sleep(0.02)
    assert store.get_run(rec.run_id)["heartbeat_at"] > first  # the run keeps it fresh
    assert abs(age_s(store.db_now())) < 5.0  # the store's clock (PostgreSQL: the server's), ISO 8601 UTC
    assert store.finish_run(rec) is None
    row = store.get_run(rec.run_id)
    assert row["outcome"] == "PASS" and len(row["measurements"]) == 1
    assert rec.run_id not in store._beats
    store.close()


def test_running_rows_of_gone_runs_become_interrupted_and_live_ones_stay(store_url):
    store = ResultsStore(store_url)
    cases = {  # run id: (host, pid, heartbeat age s, outcome after listing)
        "20260101-000000-000001": (host_name(), os.getpid(), 1.0, RUNNING),  # this live process
        "20260101-000000-000002": (host_name(), _dead_pid(), 1.0, INTERRUPTED),  # here, process gone
        "20260101-000000-000003": ("other-station", 4242, 1.0, RUNNING),  # another station's live run
        "20260101-000000-000004": ("other-station", 4242, 600.0, INTERRUPTED),  # stale heartbeat
        "20260101-000000-000005": (host_name(), os.getpid(), 600.0, INTERRUPTED),  # stale even if pid is reused
    }
    for run_id, (host, pid, age, _) in cases.items():
        store.save_doc(_running_doc(run_id, host=host, pid=pid, beat_age_s=age))
    rows = {r["run_id"]: r for r in store.list_runs()}
    assert {k: r["outcome"] for k, r in rows.items()} == {k: v[3] for k, v in cases.items()}
    gone = rows["20260101-000000-000002"]
    assert gone["raw_file"] == "/data/runs/20260101-000000-000002.h5" and gone["safe_state"] is False
    assert gone["end_reason"].startswith("interrupted: ") and gone["finished_at"] == gone["heartbeat_at"]
    # a re-open reaps too, and a row already final is never touched
    assert ResultsStore(store_url).reap() == []


def test_store_that_refuses_writes_keeps_the_record_in_the_spool_until_sync(tmp_path):
    db = tmp_path / "results.sqlite"
    ResultsStore(db).close()  # an existing store, then opened read-only
    spool_dir = tmp_path / "runs" / "spool"
    ro = ResultsStore(f"sqlite:///file:{db}?mode=ro&uri=true", offline_ok=True, spool_dir=spool_dir)
    rec = _record("20260101-000000-bbbbbb")
    notes = ro.begin_run(rec)
    assert len(notes) == 1 and "readonly database" in notes[0] and str(spool_dir) in notes[0]
    msg = ro.finish_run(rec)
    assert "\n" not in msg and "readonly database" in msg and "gyrobench runs --sync" in msg
    assert [p.name for p in Spool(spool_dir).pending()] == ["20260101-000000-bbbbbb.json"]
    store = ResultsStore(db, spool_dir=spool_dir)
    assert store.list_runs() == []
    assert store.sync() == (["20260101-000000-bbbbbb"], [])
    row = store.get_run("20260101-000000-bbbbbb")
    assert row["outcome"] == "PASS" and row["seed"] == 3_000_000_000 and row["truth"] == {"rate_dps": 100.0}
    assert row["measurements"][0]["value"] == 100.01 and row["measurements"][0]["high"] == 100.5
    assert Spool(spool_dir).pending() == []


def test_postgresql_down_spools_then_sync_submits(pg_url, tmp_path):
    with pytest.raises(StoreError, match=r"^results store postgresql\+psycopg://postgres@127.0.0.1:1/nowhere: "):
        ResultsStore(DOWN_PG)
    down = ResultsStore(DOWN_PG, offline_ok=True, spool_dir=tmp_path / "spool")
    assert down.open_error and "\n" not in down.open_error
    rec = _record("20260101-000000-cccccc", outcome="FAIL")
    assert len(down.begin_run(rec)) == 1
    assert "gyrobench runs --sync" in down.finish_run(rec)
    store = ResultsStore(pg_url, spool_dir=tmp_path / "spool")
    assert store.sync() == (["20260101-000000-cccccc"], [])
    assert store.get_run("20260101-000000-cccccc")["outcome"] == "FAIL"


def test_spooled_running_record_of_a_dead_process_goes_in_as_interrupted(store_url, tmp_path):
    spool = Spool(tmp_path / "spool")
    spool.put(_running_doc("20260101-000000-dddddd", host=host_name(), pid=_dead_pid(), beat_age_s=1.0))
    spool.put(_running_doc("20260101-000000-eeeeee", host=host_name(), pid=os.getpid(), beat_age_s=1.0))
    store = ResultsStore(store_url, spool_dir=spool.dir)
    assert store.sync() == (["20260101-000000-dddddd"], [])  # the live run's record waits for that run
    assert store.get_run("20260101-000000-dddddd")["outcome"] == INTERRUPTED
    assert [p.stem for p in spool.pending()] == ["20260101-000000-eeeeee"]


CHILD = """
import sys, time
from bench.engine import RunRecord
from bench.results import ResultsStore
url, run_id, t0 = sys.argv[1], sys.argv[2], float(sys.argv[3])
time.sleep(max(0.0, t0 - time.time()))
store = ResultsStore(url)
store.save_run(RunRecord(run_id=run_id, procedure="p", params={}, station_id="s", simulated=True,
                         started_at="2026-01-01T00:00:00+00:00", seed=2**63 - 1))
"""


def test_processes_creating_a_fresh_store_at_once_all_succeed(store_url):
    """Before the migration lock, 3 of 27 processes failed with 'table runs already exists'."""
    n = 8
    t0 = time.time() + 3.0  # all open the store at this wall time, once their imports are done
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", CHILD, store_url, f"20260101-000000-{i:06d}", repr(t0)],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for i in range(n)
    ]
    results = [(p.wait(timeout=120), p.stderr.read()) for p in procs]
    assert results == [(0, "")] * n
    store = ResultsStore(store_url)
    assert store.revision() == ResultsStore.head()
    assert len(store.list_runs(limit=100)) == n


def test_postgresql_without_its_driver_names_the_extra(monkeypatch, capsys):
    from bench.cli import main

    monkeypatch.setitem(sys.modules, "psycopg", None)  # as if psycopg were not installed
    with pytest.raises(StoreError, match=r"driver 'psycopg' is not installed; pip install 'gyrobench\[postgres\]'"):
        ResultsStore("postgresql://bench@db.example/results")
    assert main(["runs", "--results", "postgresql://bench@db.example/results"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "gyrobench[postgres]" in err and "Traceback" not in err


def test_a_late_start_never_hides_a_runs_end(store_url):
    """A start row that reaches the store after the run's final record (a server that hung, then
    answered) leaves the final record as it is."""
    store = ResultsStore(store_url)
    rec = _record("20260101-000000-ffffff")
    store.save_doc(ResultsStore.record_doc(rec))
    store.save_doc(ResultsStore.record_doc(rec, outcome=RUNNING))
    assert store.get_run(rec.run_id)["outcome"] == "PASS"


def test_passwords_are_masked_in_urls_and_connection_strings():
    from bench.results.redact import redact, redact_text

    assert redact_text("postgresql+psycopg://bench:p@ss:wd@db.lab:5432/r") == "postgresql+psycopg://bench:***@db.lab:5432/r"
    assert redact_text("host=db password='a b' user=x") == "host=db password=*** user=x"
    assert redact_text("postgresql://bench@db.lab/r?sslmode=require") == "postgresql://bench@db.lab/r?sslmode=require"
    assert redact({"keys": {"results": "postgresql://u:pw@h/db"}, "n": 3}) == {"keys": {"results": "postgresql://u:***@h/db"},
                                                                           "n": 3}
