"""A lot of N units (default 50) through the operator station (bench/gui/operator_station.py, the
window itself under offscreen Qt) on S concurrent simulated stations (default 8, one process each,
station ids opst-1..S, each with its own Ed25519 key) against one line database (PostgreSQL: a
fresh schema on $GYROBENCH_TEST_PG_URL or --db; else SQLite).  Each station logs its operator in
from the database's `operators` table, scans its serials one by one (keyboard-wedge: the text, then
Enter), answers Yes to the fixture and table-spin prompts and reads the large verdict.  Reported:
wall time, units per hour (wall), units scanned against records in the database and on disk
(records lost must be 0), the verdict counts, and `line verify` of each station's lot.

Measured at this commit (PostgreSQL 15 from .ci/start-postgres, ci-spin, 50 units on 8 concurrent
stations, a 2-core machine shared with other work, load average about 13-15): wall 118.2 s, 1523
units/h (wall), 50 records in the database and 50 on disk (0 lost), 50 PASS shown and recorded
(the window and the database agree), 0 broken chains/signatures/raw files over the 8 lots.

Run: URL=$(.ci/start-postgres); GYROBENCH_TEST_PG_URL=$URL .venv/bin/python benchmarks/operator_lot.py \
         [--units 50] [--stations 8] [--sequence ci-spin] [--keep DIR]; .ci/start-postgres --stop $URL
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


def worker(args: argparse.Namespace) -> int:
    """One station's operator: log in, then each serial scanned and run in the window (offscreen)."""
    os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
    from PySide6.QtWidgets import QApplication

    from bench.gui.operator_station import OperatorStation

    app = QApplication.instance() or QApplication([])
    win = OperatorStation(args.station, sequence=args.sequence, runs_dir=args.runs_dir, db=args.db,
                          seed=args.seed, lot=args.lot)
    win.show()
    out: dict = {"outcomes": [], "records": []}
    try:
        app.processEvents()
        if win.operator.findText(args.operator) < 0:
            raise SystemExit(f"operator {args.operator!r} is not offered at login: {win.message.text()}")
        win.operator.setCurrentText(args.operator)
        if not win.log_in():
            raise SystemExit(f"login refused: {win.message.text()}")
        for serial in args.serials.split(","):
            done = len(win.units_done)
            win.serial_field.setText(serial)
            win.serial_field.returnPressed.emit()  # the scanner's Enter
            while len(win.units_done) == done:
                app.processEvents()
                if win.waiting():
                    win.yes_button.click()
                time.sleep(0.002)
            app.processEvents()
            out["outcomes"].append([serial, win.verdict.text(), win.reason.text()])
        out["records"] = [r.get("record_file") for r in win.records]
        out["db_errors"] = [r["db_error"] for r in win.records if r.get("db_error")]
    finally:
        win.close()
    print(json.dumps(out))
    return 0


def main() -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--units", type=int, default=50)
    p.add_argument("--stations", type=int, default=8)
    p.add_argument("--sequence", default="ci-spin")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--db", default=None)
    p.add_argument("--keep", default=None, help="keep the runs and records in this folder")
    p.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--station", help=argparse.SUPPRESS)
    p.add_argument("--serials", help=argparse.SUPPRESS)
    p.add_argument("--operator", help=argparse.SUPPRESS)
    p.add_argument("--runs-dir", help=argparse.SUPPRESS)
    p.add_argument("--lot", default="", help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.worker:
        return worker(args)
    drop = None
    url = args.db
    if url is None and os.environ.get("GYROBENCH_TEST_PG_URL"):
        url, drop = fresh_pg_schema(os.environ["GYROBENCH_TEST_PG_URL"])
    runs = Path(args.keep or tempfile.mkdtemp(prefix="gyrobench-oplot-"))
    runs.mkdir(parents=True, exist_ok=True)
    url = url or str(runs / "results.sqlite")
    from sqlalchemy import text

    from bench.line.db import LineDB

    db = LineDB(url)  # the schema, then the operators the stations log in from
    with db.engine.begin() as conn:
        conn.execute(text("CREATE TABLE operators (name VARCHAR(64) PRIMARY KEY, active BOOLEAN)"))
        for k in range(1, args.stations + 1):
            conn.execute(text("INSERT INTO operators VALUES (:n, TRUE)"), {"n": f"operator {k}"})
    db.close()
    base = STATION_OF.get(args.sequence, "sim-hrg")
    share = [args.units // args.stations + (1 if k < args.units % args.stations else 0) for k in range(args.stations)]
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1]), "OPENBLAS_NUM_THREADS": "1",
           "QT_QPA_PLATFORM": "offscreen"}
    procs, trusted, scanned = [], set(), []
    t0 = time.perf_counter()
    for k, n in enumerate(share, 1):
        if n == 0:
            continue
        st, public = keyed_station_copy(runs, base, f"opst-{k}")
        trusted.add(public)
        serials = [f"OP{k}-{i:03d}" for i in range(1, n + 1)]
        scanned += serials
        cmd = [sys.executable, __file__, "--worker", "--station", str(st), "--sequence", args.sequence,
               "--serials", ",".join(serials), "--operator", f"operator {k}", "--runs-dir", str(runs),
               "--db", url, "--seed", str(args.seed + k), "--lot", f"OPL-s{k}"]
        procs.append((k, n, subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env, text=True)))
    results = []
    for k, n, proc in procs:
        out, err = proc.communicate()
        try:
            js = json.loads(out.strip().splitlines()[-1])
        except (ValueError, IndexError):
            js = {"error": err.strip()[-600:], "outcomes": []}
        results.append((k, n, proc.returncode, js))
    wall_s = time.perf_counter() - t0
    from bench.line.verify import verify_lot

    db = LineDB(url)
    try:
        in_db = {r["serial"]: r for r in db.records() if r.get("lot", "").startswith("OPL-s")}
        broken = []
        for k, _, _, _ in results:
            v = verify_lot(db, runs, f"OPL-s{k}", trusted)
            if v.breaks:
                broken.append(f"OPL-s{k}: {v.breaks[0]}")
    finally:
        db.close()
    on_disk = {json.loads(f.read_text())["serial"] for f in (runs / "line").glob("OPL-s*/*-a*.json")}
    lost_db = sorted(set(scanned) - set(in_db))
    lost_disk = sorted(set(scanned) - on_disk)
    shown: dict[str, int] = {}
    for _, _, _, js in results:
        for _s, verdict, _why in js["outcomes"]:
            shown[verdict] = shown.get(verdict, 0) + 1
    recorded: dict[str, int] = {}
    for r in in_db.values():
        recorded[r["outcome"]] = recorded.get(r["outcome"], 0) + 1
    agree = all(in_db.get(s, {}).get("outcome") in (v, "MARGINAL" if v == "CONDITIONAL" else v)
                for _, _, _, js in results for s, v, _ in js["outcomes"])
    units = len(scanned)
    print(f"| database | {'PostgreSQL' if url.startswith('postgresql') else 'SQLite'} |")
    print(f"| sequence | {args.sequence} (station {base} copies, operator station window, offscreen Qt) |")
    print(f"| units, stations | {units} on {len(results)} concurrent processes |")
    print(f"| wall time | {wall_s:.1f} s |")
    print(f"| units per hour (wall) | {3600 * units / wall_s:.0f} |")
    print(f"| records in the database / on disk | {len(in_db)} / {len(on_disk)} |")
    print(f"| records lost (database, disk) | {len(lost_db)}, {len(lost_disk)} {(lost_db + lost_disk)[:3]} |")
    print(f"| verdicts shown | {dict(sorted(shown.items()))} |")
    print(f"| outcomes recorded | {dict(sorted(recorded.items()))} (agree with the window: {agree}) |")
    print(f"| lots whose chain/signature/raw files broke | {len(broken)} {broken[:2]} |")
    for k, _n, rc, js in results:
        if "error" in js or rc:
            print(f"station opst-{k}: exit {rc}: {js.get('error', '')}", file=sys.stderr)
    if drop is not None and not args.keep:
        drop()
    return 0 if not lost_db and not lost_disk and not broken and agree else 1


if __name__ == "__main__":
    sys.exit(main())
