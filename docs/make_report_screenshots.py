"""Remake docs/report_<procedure>.png: a full default-parameter run of each procedure on its
simulated station (seed 0), its report page, and a full-page screenshot of that page in headless
Chromium (bench.reporting.browser), 1280 px wide.

Run: .venv/bin/python docs/make_report_screenshots.py [--runs-dir DIR] [--only NAME ...]
A runs directory that already holds the runs (runs.json, written by an earlier call) is reused:
`--reuse` skips the recording.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

#: procedure -> simulated station; every parameter at its default
STATIONS = {"hrg-damping": "sim-hrg", "hrg-free-decay": "sim-hrg", "mems-sweep": "sim-mems", "table-spin": "sim-hrg"}


def record(name: str, runs_dir: Path, seed: int) -> Path:
    """One full default-parameter run of the procedure on its simulated station."""
    from bench.composition.sim_station import SimStation
    from bench.engine import Runner
    from procedures import find_procedure

    station = SimStation(STATIONS[name], seed=seed).open()
    try:
        rec = Runner(station, runs_dir=runs_dir, operator="A. Tester", duts=["SN-0042"]).run(find_procedure(name), {})
    finally:
        station.close()
    if rec.outcome not in ("COMPLETE", "PASS"):
        raise SystemExit(f"{name}: the run ended {rec.outcome}: {rec.end_reason}")
    return Path(rec.raw_file)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs-dir", type=Path, default=None)
    ap.add_argument("--only", nargs="*", default=list(STATIONS))
    ap.add_argument("--reuse", action="store_true", help="reuse the runs in --runs-dir/runs.json")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    runs_dir = args.runs_dir or Path(tempfile.mkdtemp(prefix="gyrobench-shots-"))
    runs_dir.mkdir(parents=True, exist_ok=True)
    index = runs_dir / "runs.json"
    runs = json.loads(index.read_text()) if args.reuse and index.is_file() else {}
    for name in args.only:
        if name not in runs:
            t0 = time.perf_counter()
            runs[name] = str(record(name, runs_dir, args.seed))
            print(f"{name}: recorded {runs[name]} in {time.perf_counter() - t0:.1f} s", flush=True)
            index.write_text(json.dumps(runs, indent=1))

    from bench.reporting import write_report
    from bench.reporting.browser import screenshot

    for name in args.only:
        page = write_report(runs[name], output=runs_dir / f"report_{name}.html")[0]
        png = screenshot(page, ROOT / "docs" / f"report_{name}.png", runs_dir / "profile", full_page=True)
        print(f"{name}: {png.relative_to(ROOT)} from {page}", flush=True)


if __name__ == "__main__":
    main()
