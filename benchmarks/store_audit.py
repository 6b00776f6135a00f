"""Store audit: the results store against a real PostgreSQL server that is black-holed (SIGSTOP of
its processes), restarted, fed a record it refuses, or synced by four processes at once; each case
tried from outside and counted as held or not, with its wall time.
Run: .venv/bin/python benchmarks/store_audit.py [--restarts N] [--records N]
(starts and stops its own server with .ci/start-postgres; needs PostgreSQL's server binaries.)
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import subprocess
import sys
import tempfile
import time
import uuid
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from sqlalchemy import create_engine, text  # noqa: E402

from bench.engine import Result, RunRecord  # noqa: E402
from bench.engine.measurement import INTERRUPTED, RUNNING  # noqa: E402
from bench.results import ResultsStore  # noqa: E402
from bench.results.spool import Spool  # noqa: E402
from tests.pg_server import PgServer  # noqa: E402

GYROBENCH = [sys.executable, "-m", "bench.cli"]
SHORT = ["run", "table-spin", "--set", "hold_s=0.1", "--json", "--runs-dir", "runs"]


def _schema(server: PgServer) -> str:
    name = f"a_{uuid.uuid4().hex[:12]}"
    admin = create_engine(server.url, isolation_level="AUTOCOMMIT")
    with admin.connect() as conn:
        conn.execute(text(f"CREATE SCHEMA {name}"))
    admin.dispose()
    return f"{server.url}?options=-csearch_path%3D{name}"


def _record(run_id: str, operator: str = "") -> RunRecord:
    return RunRecord(run_id=run_id, procedure="table-spin", params={}, station_id="sim-hrg", simulated=True,
                     outcome="PASS", end_reason="completed", safe_state=True, operator=operator,
                     measurements=[Result("rate_dps", 100.0, "deg/s", limits=(99.5, 100.5))],
                     started_at=_dt.datetime.now(_dt.UTC).isoformat())


def hung_server_run(server: PgServer, work: Path) -> tuple[int, int, str]:
    """`gyrobench run` (0.1 s hold) against a black-holed server: ends, spools, says so in one line."""
    url = _schema(server)
    server.black_hole()
    t0 = time.monotonic()
    r = subprocess.run([*GYROBENCH, *SHORT, "--results", url], cwd=work, capture_output=True, text=True, timeout=600)
    elapsed = time.monotonic() - t0
    server.resume()
    js = json.loads(r.stdout)
    told = [ln for ln in r.stderr.splitlines() if "no answer for" in ln]
    held = (r.returncode == 1 and (work / "runs" / "spool" / f"{js['run_id']}.json").is_file() and len(told) == 1
            and elapsed < 45)
    said = told[0][11:] if told else "-"
    return 1, int(held), f"exit {r.returncode} after {elapsed:.1f} s (run {js['wall_s']:.2f} s); told: {said}"


def hung_mid_run(server: PgServer, work: Path) -> tuple[int, int, str]:
    """The server stops answering after the run's start: the end waits its bound, then spools."""
    url = _schema(server)
    store = ResultsStore(url, spool_dir=work / "spool-mid", notify=None)
    rec = _record("20260101-000000-m00001")
    store.begin_run(rec)
    server.black_hole()
    t0 = time.monotonic()
    msg = store.finish_run(rec) or ""
    elapsed = time.monotonic() - t0
    server.resume()
    held = "no answer in" in msg and Spool(work / "spool-mid").pending() != [] and elapsed < 15
    return 1, int(held), f"end of run waited {elapsed:.1f} s, then spooled"


def outage_liveness(server: PgServer, n: int) -> tuple[int, int, str]:
    """n live runs whose heartbeats missed 2 min (an outage): another station marks them INTERRUPTED;
    each run's next heartbeat makes it RUNNING again."""
    url = _schema(server)
    station = ResultsStore(url, notify=None)
    station.heartbeat_s = 3600.0
    recs = [_record(f"20260101-000000-o{i:05d}") for i in range(n)]
    for rec in recs:
        station.begin_run(rec)
    other = ResultsStore(url, notify=None)
    with other.engine.begin() as conn:
        conn.execute(text("UPDATE runs SET heartbeat_at = to_char((now() - interval '2 minutes') AT TIME ZONE 'UTC', "
                          "'YYYY-MM-DD\"T\"HH24:MI:SS.US\"+00:00\"')"))
    marked = sum(r["outcome"] == INTERRUPTED for r in other.list_runs(limit=1000))
    for rec in recs:
        station.heartbeat(rec.run_id)
    back = sum(r["outcome"] == RUNNING for r in other.list_runs(limit=1000))
    station.close()
    return n, back, f"{marked} marked INTERRUPTED during the outage, {back} RUNNING at their next heartbeat"


def restart_before_end(server: PgServer, work: Path, n: int) -> tuple[int, int, str]:
    """pg_ctl restart 1.5 s before a run's end: the record goes in, not to the spool."""
    url = _schema(server)
    held = 0
    for i in range(n):
        store = ResultsStore(url, spool_dir=work / f"spool-restart-{i}", notify=None)
        store.heartbeat_s = 3600.0
        rec = _record(f"20260101-000000-r{i:05d}")
        store.begin_run(rec)
        server.restart()
        time.sleep(1.5)
        held += store.finish_run(rec) is None and Spool(work / f"spool-restart-{i}").pending() == []
        store.close()
    return n, held, f"{held} of {n} records stored after a restart"


def poison_record(server: PgServer, work: Path, n: int) -> tuple[int, int, str]:
    """n good spooled records with a 10 kB operator and a NOT NULL violation among them: the two are
    quarantined with their reasons, the n go in; the next sync is clean."""
    url = _schema(server)
    spool = Spool(work / "spool-poison")
    for i in range(n):
        spool.put(ResultsStore.record_doc(_record(f"20260101-000000-p{i:05d}")))
        if i == n // 2:
            spool.put(ResultsStore.record_doc(_record(f"20260101-000000-p{i:05d}x", operator="x" * 10_000)))
            bad = ResultsStore.record_doc(_record(f"20260101-000000-p{i:05d}y"))
            bad["run"]["procedure"] = None
            spool.put(bad)
    store = ResultsStore(url, spool_dir=spool.dir, notify=None)
    submitted, _ = store.sync()
    again = store.sync()
    held = len(submitted) + (len(spool.quarantined()) == 2 and again == ([], []))
    return n + 1, held, f"{len(submitted)} of {n} good records in, {len(spool.quarantined())} quarantined, " \
                        f"next sync {'clean' if again == ([], []) else again}"


def concurrent_sync(server: PgServer, work: Path, n: int) -> tuple[int, int, str]:
    """Four `gyrobench runs --sync` at once over n spooled records: each submitted once, no failure."""
    url = _schema(server)
    spool = Spool(work / "runs" / "spool")
    for i in range(n):
        spool.put(ResultsStore.record_doc(_record(f"20260101-000000-c{i:05d}")))
    ResultsStore(url, notify=None).close()
    t0 = time.time() + 4.0
    child = ("import sys, time; time.sleep(max(0.0, float(sys.argv[1]) - time.time())); from bench.cli import main; "
             "sys.exit(main(['runs', '--sync', '--runs-dir', 'runs', '--results', sys.argv[2]]))")
    procs = [subprocess.Popen([sys.executable, "-c", child, repr(t0), url], cwd=work, stdout=subprocess.DEVNULL,
                              stderr=subprocess.PIPE, text=True) for _ in range(4)]
    out = [(p.wait(timeout=600), p.stderr.read()) for p in procs]
    clean = sum(rc == 0 and "duplicate key" not in err and "Traceback" not in err for rc, err in out)
    counts = [int(err.split("submitted ", 1)[1].split()[0]) if "submitted " in err else 0 for _, err in out]
    stored = len(ResultsStore(url, notify=None).list_runs(limit=10 * n))
    return 4, clean * (sum(counts) == n == stored), f"submitted {counts} (sum {sum(counts)} of {n}), {stored} stored"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--restarts", type=int, default=3)
    ap.add_argument("--records", type=int, default=24)
    ap.add_argument("--live-runs", type=int, default=8)
    args = ap.parse_args()
    server = PgServer()
    rows = []
    try:
        with tempfile.TemporaryDirectory() as tmp:
            work = Path(tmp)
            cases: list[tuple[str, Callable[[], tuple[int, int, str]]]] = [
                ("hung server, whole run", lambda: hung_server_run(server, work / "hung")),
                ("hung server, mid run", lambda: hung_mid_run(server, work)),
                ("outage > 60 s, liveness", lambda: outage_liveness(server, args.live_runs)),
                ("restart 1.5 s before end", lambda: restart_before_end(server, work, args.restarts)),
                ("poison record", lambda: poison_record(server, work, args.records)),
                ("4 concurrent syncs", lambda: concurrent_sync(server, work / "sync", args.records)),
            ]
            (work / "hung").mkdir()
            (work / "sync").mkdir()
            for name, case in cases:
                t0 = time.monotonic()
                tried, held, note = case()
                rows.append((name, tried, held, time.monotonic() - t0, note))
                print(f"{name:<26} {tried:>5} {held:>5} {rows[-1][3]:>8.1f}  {note}", file=sys.stderr, flush=True)
    finally:
        server.stop()
    print(f"{'case':<26} {'tried':>5} {'held':>5} {'seconds':>8}  note")
    for name, tried, held, secs, note in rows:
        print(f"{name:<26} {tried:>5} {held:>5} {secs:>8.1f}  {note}")
    return 0 if all(tried == held for _, tried, held, _, _ in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
