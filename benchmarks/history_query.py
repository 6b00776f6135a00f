"""The history browser on a large results store: how long its queries take and how long the
window's event loop stalls while it searches.

Fills a fresh SQLite store (or `--url`) with `--runs` runs (procedures, stations, outcomes, DUTs
and dates spread at random, seeded), then times `find_runs` for each kind of filter (median of
`--repeat`), and opens the `HistoryBrowser` (offscreen) while a 10 ms QTimer measures how late
the event loop runs during the queries.

    QT_QPA_PLATFORM=offscreen .venv/bin/python benchmarks/history_query.py [--runs 10000]
"""

from __future__ import annotations

import argparse
import datetime as dt
import os
import statistics
import tempfile
import time

import numpy as np


def fill(store, n_runs: int, seed: int = 0) -> None:
    """n_runs runs written in one transaction per 1000 (as many stations would over years)."""
    from sqlalchemy import insert

    from bench.results.schema import run_duts, runs

    rng = np.random.default_rng(seed)
    procs = ["hrg-damping", "hrg-free-decay", "mems-sweep", "table-spin"]
    stations = [f"line-{i}" for i in range(6)] + ["sim-hrg", "sim-mems"]
    outcomes = ["COMPLETE"] * 6 + ["PASS"] * 6 + ["FAIL", "MARGINAL", "ERROR", "ABORTED", "INTERRUPTED"]
    t0 = dt.datetime(2025, 1, 1, tzinfo=dt.UTC)
    for start in range(0, n_runs, 1000):
        rows, duts = [], []
        for i in range(start, min(n_runs, start + 1000)):
            when = (t0 + dt.timedelta(seconds=float(rng.uniform(0, 365 * 86400)))).isoformat()
            run_id = f"bench-{i:06d}"
            rows.append({"run_id": run_id, "procedure": procs[rng.integers(len(procs))],
                         "station_id": stations[rng.integers(len(stations))],
                         "simulated": False, "outcome": outcomes[rng.integers(len(outcomes))], "end_reason": "",
                         "safe_state": True, "started_at": when, "finished_at": when, "simulated_s": 600.0,
                         "wall_s": 600.0, "raw_file": f"/data/runs/{run_id}.h5", "software_version": "bench",
                         "operator": "", "seed": i, "params": {"record_s": 300.0}, "host": "h", "pid": 1,
                         "heartbeat_at": when})
            for slot in range(int(rng.integers(0, 4))):
                duts.append({"run_id": run_id, "slot": slot, "serial": f"HRG-{rng.integers(0, 5000):05d}"})
        with store.engine.begin() as conn:
            conn.execute(insert(runs), rows)
            if duts:
                conn.execute(insert(run_duts), duts)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=10_000)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--url", default=None, help="a store URL (default: a fresh SQLite file)")
    args = ap.parse_args()
    os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
    from bench.results import ResultsStore
    from bench.results.query import RunFilter, find_runs

    tmp = tempfile.mkdtemp(prefix="history-bench-")
    url = args.url or os.path.join(tmp, "results.sqlite")
    store = ResultsStore(url)
    t = time.perf_counter()
    fill(store, args.runs)
    print(f"store {store.display_url}: {args.runs} runs written in {time.perf_counter() - t:.1f} s")
    cases = {
        "no filter (newest 5000)": RunFilter(),
        "procedure": RunFilter(procedure="hrg-damping"),
        "station": RunFilter(station_id="line-3"),
        "outcome": RunFilter(outcome="FAIL"),
        "DUT (substring)": RunFilter(dut="HRG-012"),
        "date range (one month)": RunFilter(since=dt.date(2025, 6, 1), until=dt.date(2025, 6, 30)),
        "all five": RunFilter(procedure="hrg-damping", station_id="line-3", outcome="PASS", dut="HRG-0",
                              since=dt.date(2025, 3, 1), until=dt.date(2025, 9, 30)),
    }
    print(f"{'filter':<26} {'rows':>6} {'matches':>8} {'median ms':>10} {'max ms':>8}")
    for name, flt in cases.items():
        times = []
        for _ in range(args.repeat):
            t = time.perf_counter()
            rows, total = find_runs(store, flt)
            times.append(time.perf_counter() - t)
        print(f"{name:<26} {len(rows):>6} {total:>8} {statistics.median(times) * 1e3:>10.1f} {max(times) * 1e3:>8.1f}")

    from PySide6.QtCore import QTimer
    from PySide6.QtWidgets import QApplication

    from bench.gui.history import HistoryBrowser

    app = QApplication.instance() or QApplication(["bench"])
    lateness: list[float] = []
    last = [time.perf_counter()]

    def tick() -> None:
        now = time.perf_counter()
        lateness.append(now - last[0] - 0.010)
        last[0] = now

    timer = QTimer()
    timer.setInterval(10)
    timer.timeout.connect(tick)
    timer.start()
    t = time.perf_counter()
    win = HistoryBrowser(store.url)
    win.show()
    opened = time.perf_counter() - t
    answers = []
    for combo_text in ("hrg-damping", "mems-sweep", "(any)", "table-spin", "(any)"):
        t = time.perf_counter()
        win.procedure.setCurrentText(combo_text)
        win.query()
        while win.busy() or win.count.text() == "searching...":
            app.processEvents()
            time.sleep(0.002)
        app.processEvents()
        answers.append((combo_text, win.model.rowCount(), time.perf_counter() - t))
    timer.stop()
    print(f"browser opened in {opened * 1e3:.0f} ms (its first query runs on a worker thread)")
    for text, n, s in answers:
        print(f"  procedure {text:<14} {n:>5} rows in the table after {s * 1e3:6.0f} ms")
    late = np.asarray(lateness) * 1e3
    print(f"event loop lateness during the queries (10 ms timer): median {np.median(late):.1f} ms, "
          f"p99 {np.percentile(late, 99):.1f} ms, max {late.max():.1f} ms over {len(late)} ticks")
    win.close()
    store.close()


if __name__ == "__main__":
    main()
