"""The line database and report at production scale:
- records written per second by 8 station processes at once (each saving copies of a real unit
  record as fast as it can), on SQLite and on PostgreSQL, every record counted;
- `gyrobench line report` over 10,000 unit records (values spread around a real record's, judged
  again by the limits; 10 lots, 8 stations, 20 days).
Run: .venv/bin/python benchmarks/line_db.py [--per-station 100] [--records 10000]
(PostgreSQL needs $GYROBENCH_TEST_PG_URL, e.g. from .ci/start-postgres; else it is left out.)
"""

from __future__ import annotations

import argparse
import contextlib
import copy
import datetime as dt
import io
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

STATIONS = 8


def template_record(folder: Path) -> Path:
    """A real record: one unit of ci-mems."""
    from bench.cli import main

    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        main(["line", "simulate", "--units", "1", "--seed", "3", "--sequence", "ci-mems", "--runs-dir", str(folder),
              "--json"])
    return Path(json.loads(out.getvalue().strip().splitlines()[-1])["records"][0])


def concurrent_writes(url: str, template: Path, per_station: int, folder: Path) -> tuple[float, int]:
    from bench.line.db import LineDB

    LineDB(url).close()  # migrated once, so the timing is of the writes
    procs = [subprocess.Popen([sys.executable, "-m", "bench.line.stations", url, str(folder), str(i),
                               str(per_station), "--synthetic", str(template)], stdout=subprocess.PIPE, text=True)
             for i in range(STATIONS)]
    elapsed = []
    for p in procs:
        out, _ = p.communicate()
        elapsed.append(json.loads(out.strip().splitlines()[-1])["elapsed_s"])
    db = LineDB(url)
    n, _ = db.count()
    db.close()
    return STATIONS * per_station / max(elapsed), n


def fill(url: str, template: Path, n: int, seed: int = 0) -> None:
    """n records spread around the template's values, judged again by their limits."""
    from bench.line.db import LineDB
    from bench.line.verdict import Limit, judge, worst

    rng = np.random.default_rng(seed)
    base = json.loads(template.read_text())
    db = LineDB(url)
    t0 = dt.datetime(2026, 11, 1, tzinfo=dt.UTC)
    batch = []
    for k in range(n):
        rec = copy.deepcopy(base)
        when = (t0 + dt.timedelta(minutes=3 * k)).isoformat()
        rec.update(serial=f"U{k:05d}", lot=f"L{k * 10 // n:02d}", station=f"st{k % STATIONS}", attempt=1,
                   started_at=when, ended_at=when)
        for m in rec["measurements"]:
            if m["value"] is None:
                continue
            shift = float(rng.normal(0.0, 0.03 * abs(m["value"]) + 1e-12))
            m["value"] += shift
            if m["interval"]:
                m["interval"] = [m["interval"][0] + shift, m["interval"][1] + shift]
            if m["rule"]:
                lim = Limit(m["name"], m["limits"]["low"], m["limits"]["high"], m["rule"])
                iv = None if m["interval"] is None else tuple(math.nan if x is None else x for x in m["interval"])
                m["outcome"] = judge(m["value"], iv, lim).outcome
        rec["outcome"] = worst(m["outcome"] for m in rec["measurements"] if m["rule"])
        batch.append(rec)
        if len(batch) == 500 or k == n - 1:
            db.save_many(batch)
            batch = []
    db.close()


def main() -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--per-station", type=int, default=100)
    p.add_argument("--records", type=int, default=10_000)
    args = p.parse_args()
    from bench.line.db import LineDB
    from bench.line.report import write_line_report

    tmp = Path(tempfile.mkdtemp(prefix="gyrobench-linedb-"))
    template = template_record(tmp / "tpl")
    urls = [("SQLite", f"sqlite:///{tmp / 'w.sqlite'}")]
    if os.environ.get("GYROBENCH_TEST_PG_URL"):
        sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
        from benchmarks.lot_setup import fresh_pg_schema

        pg, drop = fresh_pg_schema(os.environ["GYROBENCH_TEST_PG_URL"])
        urls.append(("PostgreSQL", pg))
    for name, url in urls:
        rate, n = concurrent_writes(url, template, args.per_station, tmp / name)
        print(f"{name}: {STATIONS} stations x {args.per_station} records: {rate:.0f} records/s "
              f"(counted {n} of {STATIONS * args.per_station}, lost {STATIONS * args.per_station - n})")
    url = f"sqlite:///{tmp / 'big.sqlite'}"
    t0 = time.perf_counter()
    fill(url, template, args.records)
    print(f"filled {args.records} records in {time.perf_counter() - t0:.0f} s (500 a transaction)")
    for lot in (None, "L03"):
        db = LineDB(url)
        t0 = time.perf_counter()
        paths = write_line_report(db, lot=lot, runs_dir=tmp)
        db.close()
        print(f"line report over {'all ' + str(args.records) if lot is None else 'lot ' + lot} records: "
              f"{time.perf_counter() - t0:.1f} s ({paths[0].stat().st_size / 1e6:.1f} MB HTML)")
    if len(urls) > 1:
        drop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
