"""Benchmark: a campaign of N `hrg-damping` runs against the same N runs by hand, two at a time (issue 38).

Target (a 2-core machine): the campaign (a LocalCluster of one worker process a core) finishes in
<= 1.15x the wall time of the N runs made by hand at full use of both cores: `gyrobench run
hrg-damping --seed S` commands, two running at any time.  Both write raw files and store rows in
a temporary folder; the seeds are the same.  Run on an idle machine:
    .venv/bin/python benchmarks/campaign_speed.py [--runs 40] [--workers 2]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TARGET = 1.15
CAMPAIGN = """[campaign]
id = "speed"
procedure = "hrg-damping"
station = "sim-hrg"

[seeds]
start = 1
count = {n}
"""


def _env() -> dict[str, str]:
    return dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])))


def by_hand(n: int, parallel: int, folder: Path) -> float:
    """N `gyrobench run` commands, `parallel` at a time: the wall time (s)."""
    def one(seed: int) -> int:
        return subprocess.run([sys.executable, "-m", "bench.cli", "run", "hrg-damping", "--seed", str(seed),
                               "--runs-dir", str(folder / "runs"), "--results", str(folder / "results.sqlite"),
                               "--json"], cwd=ROOT, env=_env(), capture_output=True, timeout=1800).returncode

    t0 = time.perf_counter()
    with ThreadPoolExecutor(parallel) as pool:
        codes = list(pool.map(one, range(1, n + 1)))
    wall = time.perf_counter() - t0
    if any(codes):
        raise SystemExit(f"by hand: {sum(1 for c in codes if c)} run(s) failed")
    return wall


def campaign(n: int, workers: int, folder: Path) -> float:
    """The same N runs as one campaign on a LocalCluster: the wall time (s), cluster start included."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "speed.toml"
    path.write_text(CAMPAIGN.format(n=n))
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "bench.cli", "campaign", str(path), "--workers", str(workers),
                           "--runs-dir", str(folder / "runs"), "--results", str(folder / "results.sqlite"),
                           "--json"], cwd=ROOT, env=_env(), capture_output=True, text=True, timeout=3600)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"campaign failed ({proc.returncode}): {proc.stderr[-1500:]}")
    out = json.loads(proc.stdout)
    if out["ran"] != n:
        raise SystemExit(f"campaign made {out['ran']} runs of {n}")
    return wall


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=40)
    ap.add_argument("--workers", type=int, default=2, help="worker processes (and runs by hand at a time)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="campaign-speed-") as tmp:
        print(f"{args.runs} hrg-damping runs, {args.workers} at a time, load average {os.getloadavg()[0]:.1f}")
        hand = by_hand(args.runs, args.workers, Path(tmp) / "hand")
        print(f"  by hand   {hand:8.1f} s  ({hand / args.runs:.2f} s a run)", flush=True)
        camp = campaign(args.runs, args.workers, Path(tmp) / "campaign")
        print(f"  campaign  {camp:8.1f} s  ({camp / args.runs:.2f} s a run)")
    ratio = camp / hand
    print(f"  load average at the end {os.getloadavg()[0]:.1f}")
    print(f"  campaign / by hand = {ratio:.3f}  (target <= {TARGET}: {'met' if ratio <= TARGET else 'NOT met'})")


if __name__ == "__main__":
    main()
