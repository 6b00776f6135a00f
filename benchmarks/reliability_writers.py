"""Reliability audit, class "concurrent writers": processes creating and writing a fresh results
store at the same instant (SQLite and PostgreSQL), plus whole `gyrobench run`s saving to one
store at once.  A writer is clean when it exits 0 with no traceback and its record is in the store;
a record is lost when it is neither in the store nor in the spool.
Run: .venv/bin/python benchmarks/reliability_writers.py [--creators N] [--runs N]
(PostgreSQL writers need $GYROBENCH_TEST_PG_URL, e.g. from .ci/start-postgres; else they are left out.)
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path

from bench.results import ResultsStore

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.lot_setup import fresh_pg_schema  # noqa: E402

CREATOR = """
import sys, time
from bench.engine import RunRecord
from bench.results import ResultsStore
url, run_id, t0 = sys.argv[1], sys.argv[2], float(sys.argv[3])
time.sleep(max(0.0, t0 - time.time()))
ResultsStore(url).save_run(RunRecord(run_id=run_id, procedure="p", params={}, station_id="s", simulated=True,
                                     started_at="2026-01-01T00:00:00+00:00", seed=2**63 - 1))
"""


def _clean(rc: int, err: str) -> bool:
    return rc == 0 and "Traceback" not in err


def creators(url: str, n: int) -> tuple[int, int, int, list[str]]:
    """n processes open a fresh store at one instant and save one run each: (tried, clean, lost, errors)."""
    t0 = time.time() + 2.0 + 0.3 * n  # after every process has imported
    ids = [f"20260101-000000-{i:06d}" for i in range(n)]
    procs = [
        subprocess.Popen([sys.executable, "-c", CREATOR, url, run_id, repr(t0)], stderr=subprocess.PIPE, text=True)
        for run_id in ids
    ]
    outs = [(p.wait(timeout=300), p.stderr.read()) for p in procs]
    stored = {r["run_id"] for r in ResultsStore(url).list_runs(limit=10 * n)}
    clean = sum(_clean(rc, err) and run_id in stored for (rc, err), run_id in zip(outs, ids, strict=True))
    errors = [err.strip().splitlines()[-1] for rc, err in outs if not _clean(rc, err)]
    return n, clean, sum(run_id not in stored for run_id in ids), errors


def runs(url: str, n: int, workdir: Path) -> tuple[int, int, int, list[str]]:
    """n `gyrobench run`s started at once on one store: (tried, clean, lost, errors)."""
    cmd = [sys.executable, "-m", "bench.cli", "run", "table-spin", "--set", "hold_s=0.1", "--json"]
    cmd += ["--results", url, "--runs-dir", str(workdir / "runs")]
    procs = [
        subprocess.Popen(
            cmd + ["--seed", str(i)], cwd=workdir, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
        )
        for i in range(n)
    ]
    outs = [(p.wait(timeout=600), *p.communicate()) for p in procs]
    stored = {r["run_id"]: r for r in ResultsStore(url).list_runs(limit=10 * n)}
    spooled = {p.stem for p in (workdir / "runs" / "spool").glob("*.json")}
    clean = lost = 0
    errors = []
    for rc, out, err in outs:
        try:
            run_id = json.loads(out)["run_id"]
        except (ValueError, KeyError):
            lost += 1
            errors.append((err.strip().splitlines() or ["no output"])[-1])
            continue
        ok = _clean(rc, err) and stored.get(run_id, {}).get("outcome") == "PASS"
        clean += ok
        lost += run_id not in stored and run_id not in spooled
        if not ok:
            errors.append((err.strip().splitlines() or [f"rc {rc}"])[-1])
    return n, clean, lost, errors




def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--creators", type=int, default=16, help="processes creating one fresh store, per engine")
    ap.add_argument("--runs", type=int, default=4, help="gyrobench runs saving to one store at once, per engine")
    args = ap.parse_args()
    pg = os.environ.get("GYROBENCH_TEST_PG_URL")
    totals = [0, 0, 0]
    with tempfile.TemporaryDirectory() as tmp:
        cases = [("sqlite", lambda: (f"sqlite:///{Path(tmp) / uuid.uuid4().hex}.sqlite", lambda: None))]
        if pg:
            cases.append(("postgresql", lambda: fresh_pg_schema(pg, "audit")))
        else:
            print("PostgreSQL: GYROBENCH_TEST_PG_URL is not set; its writers are left out")
        for engine, make in cases:
            for kind, n in (("fresh-store creators", args.creators), ("concurrent gyrobench runs", args.runs)):
                url, drop = make()
                t = time.monotonic()
                work = Path(tmp) / uuid.uuid4().hex
                work.mkdir()
                tried, clean, lost, errors = creators(url, n) if kind.startswith("fresh") else runs(url, n, work)
                drop()
                print(
                    f"{engine:<10} {kind:<26} tried {tried:>3}, clean {clean:>3}, lost {lost}  "
                    f"({time.monotonic() - t:.1f} s)"
                )
                for e in sorted(set(errors)):
                    print(f"    {errors.count(e)} x {e}")
                for i, v in enumerate((tried, clean, lost)):
                    totals[i] += v
    print(f"concurrent writers: tried {totals[0]}, clean {totals[1]} (records lost: {totals[2]})")
    return 0 if totals[0] == totals[1] and totals[2] == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
