"""A simulated lot through a line sequence (default: 50 units of eol-hrg on PostgreSQL): units per
hour in bench time (what a real line would see: the runs' simulated seconds) and in wall time
(the simulated line in lockstep), every outcome checked against the drawn truth, and the line
report's yield and Cpk checked against the JSON records.
Run: .venv/bin/python benchmarks/line_lot.py [--sequence eol-hrg] [--units 50] [--seed 1] [--db URL]
(default --db: a fresh schema on $GYROBENCH_TEST_PG_URL, e.g. from .ci/start-postgres; else SQLite.)
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.lot_setup import fresh_pg_schema  # noqa: E402


def main() -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--sequence", default="eol-hrg")
    p.add_argument("--units", type=int, default=50)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--db", default=None)
    p.add_argument("--keep", default=None, help="keep the runs and records in this folder")
    args = p.parse_args()
    from bench.cli import main as cli
    from bench.line.db import LineDB
    from bench.line.report import summarize, write_line_report

    drop = None
    url = args.db
    if url is None and os.environ.get("GYROBENCH_TEST_PG_URL"):
        url, drop = fresh_pg_schema(os.environ["GYROBENCH_TEST_PG_URL"])
    runs_dir = Path(args.keep or tempfile.mkdtemp(prefix="gyrobench-lot-"))
    url = url or str(runs_dir / "results.sqlite")
    argv = ["line", "simulate", "--units", str(args.units), "--seed", str(args.seed), "--sequence", args.sequence,
            "--runs-dir", str(runs_dir), "--db", url, "--json"]
    out = io.StringIO()
    t0 = time.perf_counter()
    with contextlib.redirect_stdout(out):
        code = cli(argv)
    wall_s = time.perf_counter() - t0
    js = json.loads(out.getvalue().strip().splitlines()[-1])
    records = [json.loads(Path(f).read_text()) for f in js["records"]]
    bench_s = sum(r["simulated_s"] for rec in records for r in rec["runs"])
    engine = "PostgreSQL" if url.startswith("postgres") else "SQLite"
    print(f"{args.sequence}: {args.units} units ({len(records)} attempts) on {engine}; outcomes {js['counts']}")
    print(f"  wrong outcomes for the drawn truth: {len(js['wrong'])}" + "".join(f"\n    {w}" for w in js["wrong"]))
    print(f"  final outcome decided by a measurement without a true value: {js['undecided_by_truth']}")
    print(f"  bench time {bench_s:.0f} s = {3600 * args.units / bench_s:.2f} units/h; "
          f"wall {wall_s:.0f} s = {3600 * args.units / wall_s:.0f} units/h (lockstep, {bench_s / wall_s:.0f}x)")
    missing = [r["serial"] for r in records if not Path(r["record_file"]).is_file()
               or any(run["sha256"] is None for run in r["runs"])]
    print(f"  records with a missing file or raw-file checksum: {len(missing)}")
    no_docs = [r["serial"] for r in records if not Path(r.get("documents", {}).get("certificate", "")).is_file()]
    comps = sum(Path(r.get("documents", {}).get("compensation", "")).is_file() for r in records)
    print(f"  attempts without a certificate: {len(no_docs)}; with a compensation file: {comps} of {len(records)}")
    db = LineDB(url)
    t1 = time.perf_counter()
    s = summarize(db, lot=js["lot"])
    paths = write_line_report(db, lot=js["lot"], runs_dir=runs_dir)
    print(f"  line report in {time.perf_counter() - t1:.1f} s: {paths[0]}")
    last = {}
    for r in records:
        last[r["serial"]] = r
    (row,) = s["by_lot"]
    ok_yield = row["final_yield"] == sum(r["outcome"] == "PASS" for r in last.values()) / len(last)
    worst_cpk = 0.0
    for m in s["measures"]:
        vals = np.array([x["value"] for r in last.values() for x in r["measurements"]
                         if x["name"] == m["name"] and x["value"] is not None and x["rule"]])
        if m["cpk"] is None or len(vals) < 2:
            continue
        sides = [s_ for s_ in ((m["high"] - vals.mean()) if m["high"] is not None else None,
                               (vals.mean() - m["low"]) if m["low"] is not None else None) if s_ is not None]
        cpk = min(sides) / (3 * vals.std(ddof=1))
        worst_cpk = max(worst_cpk, abs(cpk - m["cpk"]) / abs(cpk))
        print(f"    {m['name']:<22} n {m['n']:>3}  Cp {m['cp'] if m['cp'] is None else round(m['cp'], 3)}  "
              f"Cpk {m['cpk']:.3f}  (from the records {cpk:.3f})")
    print(f"  report yield agrees with the records: {ok_yield}; largest Cpk difference {worst_cpk:.1e}")
    db.close()
    if drop is not None:
        drop()
    return 0 if code == 0 and ok_yield and worst_cpk < 1e-9 and not missing else 1


if __name__ == "__main__":
    sys.exit(main())
