"""A lot of N units (default 50) through `gyrobench line simulate` on S concurrent simulated
stations (default 8, one process each, station ids bench-1..S) against one line database
(PostgreSQL: a fresh schema on $GYROBENCH_TEST_PG_URL or --db, e.g. from .ci/start-postgres; else
SQLite): wall time, units per hour (wall), records in the database against records on disk, every
outcome checked against its drawn truth, `line verify` of each station's lot, and the line report
(with --pdf) over the whole database.

Measured at this commit (PostgreSQL 15 from .ci/start-postgres, ci-mems, 50 units on 8 concurrent
stations, a 2-core machine shared with other work, load average about 9-15): wall 137.8 s, 1306 units/h
(wall), 50 records on disk and 50 attempts in the database, 0 outcomes wrong for their truth, 0 broken
chains/signatures/raw files over the 8 lots, the report and its PDF written (a 16-unit run: 101 s).

Run: URL=$(.ci/start-postgres); GYROBENCH_TEST_PG_URL=$URL .venv/bin/python benchmarks/line_lot_50.py \
         [--units 50] [--stations 8] [--sequence ci-mems] [--keep DIR]; .ci/start-postgres --stop $URL
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.lot_setup import STATION_OF, fresh_pg_schema, keyed_station_copy  # noqa: E402


def main() -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--units", type=int, default=50)
    p.add_argument("--stations", type=int, default=8)
    p.add_argument("--sequence", default="ci-mems")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--db", default=None)
    p.add_argument("--keep", default=None, help="keep the runs, records and report in this folder")
    args = p.parse_args()
    drop = None
    url = args.db
    if url is None and os.environ.get("GYROBENCH_TEST_PG_URL"):
        url, drop = fresh_pg_schema(os.environ["GYROBENCH_TEST_PG_URL"])
    runs = Path(args.keep or tempfile.mkdtemp(prefix="gyrobench-lot50-"))
    runs.mkdir(parents=True, exist_ok=True)
    url = url or str(runs / "results.sqlite")
    base = STATION_OF.get(args.sequence, "sim-hrg")
    share = [args.units // args.stations + (1 if k < args.units % args.stations else 0) for k in range(args.stations)]
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1]), "OPENBLAS_NUM_THREADS": "1"}
    procs = []
    trusted: set[str] = set()
    t0 = time.perf_counter()
    for k, n in enumerate(share, 1):
        if n == 0:
            continue
        st, public = keyed_station_copy(runs, base, f"bench-{k}")
        trusted.add(public)
        cmd = [sys.executable, "-m", "bench.cli", "line", "simulate", "--units", str(n), "--seed", str(args.seed + k),
               "--sequence", args.sequence, "--station", str(st), "--lot", f"L50-s{k}", "--runs-dir", str(runs),
               "--db", url, "--json"]
        procs.append((k, n, subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env, text=True)))
    results = []
    for k, n, proc in procs:
        out, err = proc.communicate()
        try:
            js = json.loads(out.strip().splitlines()[-1])
        except (ValueError, IndexError):
            js = {"error": err.strip()[-400:]}
        results.append((k, n, proc.returncode, js))
    wall_s = time.perf_counter() - t0
    from bench.line.db import LineDB
    from bench.line.report import write_line_report
    from bench.line.verify import verify_lot

    db = LineDB(url)
    try:
        attempts, measurements = db.count()
        on_disk = len(list((runs / "line").glob("L50-s*/*-a*.json")))
        wrong = [w for _, _, _, js in results for w in js.get("wrong", [])]
        broken = []
        for k, _, _, _ in results:
            v = verify_lot(db, runs, f"L50-s{k}", trusted)
            if v.breaks:
                broken.append(f"L50-s{k}: {v.breaks[0] if v.breaks else '?'}")
        report = write_line_report(db, output=runs / "line" / "report-L50.html", pdf=True, runs_dir=runs)
    finally:
        db.close()
    units = sum(n for _, n, _, _ in results)
    print(f"| database | {'PostgreSQL' if url.startswith('postgresql') else 'SQLite'} |")
    print(f"| sequence | {args.sequence} |")
    print(f"| units, stations | {units} on {len(results)} concurrent processes |")
    print(f"| wall time | {wall_s:.1f} s |")
    print(f"| units per hour (wall) | {3600 * units / wall_s:.0f} |")
    print(f"| records on disk / attempts in the database | {on_disk} / {attempts} ({measurements} measurements) |")
    print(f"| exit codes | {sorted({rc for _, _, rc, _ in results})} |")
    print(f"| outcomes wrong for their truth | {len(wrong)} |")
    print(f"| lots whose chain/signature/raw files broke | {len(broken)} {broken[:2]} |")
    print(f"| report | {', '.join(str(x) for x in report)} |")
    for k, _n, rc, js in results:
        if "error" in js:
            print(f"station bench-{k}: exit {rc}: {js['error']}", file=sys.stderr)
    if drop is not None and not args.keep:
        drop()
    return 0 if not wrong and not broken and on_disk == attempts else 1


if __name__ == "__main__":
    sys.exit(main())
