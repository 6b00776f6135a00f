"""How much bench time a lockstep run's raw file may lack on disk: the run goes through the CLI in
this process with the recorder's flush wrapped, and the largest bench-time gap between two flushes
is what a disk that fills (or a kill) can lose (issue 39: the README said "flushed at least every
second of data").

Run: .venv/bin/python benchmarks/flush_cadence.py [procedure] [--set NAME=VALUE ...]
     (default: table-spin --set hold_s=60 on sim-hrg in lockstep)

2026-11-28, 2 shared cores, hrg-damping in lockstep (1110 bench s), the second of two runs:
  before (a bench second AND a quarter wall second or 4096 rows): 81 flushes, largest gap 40 bench s
    (median 4.4 s), 16.2 s wall
  after (every bench second, or every wall second): 926 flushes, largest gap 1.31 bench s (median 1.2:
    a flush waits for the event that crosses the second), 11.2 s wall: no cost to see on this machine
"""

from __future__ import annotations

import sys
import tempfile
import time

import numpy as np

import bench.recorder as br
from bench.cli import main as cli


def measure(args: list[str]) -> dict[str, float]:
    """Largest and median bench-time and wall-time gaps between flushes of one run (s)."""
    at: list[tuple[float, float]] = []
    real = br.Recorder._flush

    def flush(self):
        real(self)
        at.append((self._last_t or 0.0, time.monotonic()))

    br.Recorder._flush = flush
    try:
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.monotonic()
            code = cli([*args, "--runs-dir", tmp, "--results", f"{tmp}/r.sqlite", "--json"])
            wall_s = time.monotonic() - t0
    finally:
        br.Recorder._flush = real
    t = np.array(at)
    gaps_sim, gaps_wall = np.diff(t[:, 0]), np.diff(t[:, 1])
    return {"exit": code, "wall_s": wall_s, "flushes": len(t), "bench_s": float(t[-1, 0]),
            "max_gap_bench_s": float(gaps_sim.max()), "median_gap_bench_s": float(np.median(gaps_sim)),
            "max_gap_wall_s": float(gaps_wall.max())}


if __name__ == "__main__":
    extra = sys.argv[1:] or ["table-spin", "--set", "hold_s=60"]
    for attempt in ("warm-up", "measured"):
        res = measure(["run", *extra])
        print(f"{attempt}: " + " ".join(f"{k}={v:.3g}" if isinstance(v, float) else f"{k}={v}" for k, v in res.items()),
              file=sys.stderr)
