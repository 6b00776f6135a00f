"""Benchmark: `make test`'s parallel pass (`pytest -m "not serial"` in xdist workers), its wall, its
CPU, the machine's load while it ran, and how its workers end (issue 36: the pass <= ~230 s).

Runs the pass once in this checkout with `-n WORKERS --dist DIST` (PostgreSQL from
$GYROBENCH_TEST_PG_URL, CI=true, bytecode written, Qt offscreen: `make test`'s environment), with
$GYROBENCH_TEST_CPU_LOG set, and prints: the wall; the CPU of the whole pass (user + system of
pytest and every process it waited for); the load average sampled every 10 s (other users of the
2 cores stretch the wall, not the CPU); per worker its tests, busy seconds and when its last test
ended (a worker that ends long after the others is a straggler); the costliest files. Give the
CPU log to `python tests/xdist_units.py LOG...` to refresh tests/costs_s.tsv (the files' order).
A pass takes 6-8 min on the shared 2 cores: run it rarely, never beside another suite.

Run: .venv/bin/python benchmarks/suite_pass.py [--workers 4] [--dist loadfile] [--log FILE]
(--dist worksteal and 4 workers, `make test`'s, by default; the FAILED and ERROR lines are printed)

Measured 2026-11-28 on the 2 shared cores, one pass each (CPU: user + system of the whole pass; the
load average sampled every 10 s includes the pass's own workers):
  worksteal -n 3 (before, 14:20): 1493 passed, 441 s (+25 s kernel compile), CPU 602 s, 128 % of a core, load mean 5.6
  loadfile  -n 3 (14:34):         1496 passed, 472 s, CPU 614 s, 129 %, load mean 7.3 (1.3-11.0)
  loadfile  -n 4 (14:45):         1496 passed, 372 s, CPU 630 s, 169 %, load mean 5.9 (1.4-8.2);
                                  the four workers' last tests ended within 0.1 s of each other
  at the end, idle (load ~1 before), the same tree (1525 tests): loadfile -n 4 428 s (in .ci/run),
                                  worksteal -n 3 348 s: `make test` keeps worksteal -n 3
  2026-11-28 21:08-21:30, one tree (the store-outage waits in this pass), interleaved 4, 3, 4, 3:
                                  -n 4 275 s (CPU 485, load mean 4.1), -n 3 332 s (CPU 540, 4.4),
                                  -n 4 285 s (CPU 508, 5.2), -n 3 402 s (CPU 502, 5.9: other users);
                                  the same pass's CPU moves 10 % between runs on this VM, so the wall
                                  per CPU second compares them: 0.56 on 4 workers, 0.62-0.80 on 3.
                                  `make test` moved to 4.  One -n 4 pass failed two tests: a 0.3 s
                                  reply timeout in test_rate_table (now the drivers' 1 s) and a
                                  SIGKILLed recorder's file with rows not as written (not reproduced
                                  in 160 kills since: left open, see the stop's note)
  2026-11-29, e9d8406 (before) against this stop's trees, interleaved, two rounds (benchmarks/
                                  suite_profile.py's profile chose the changes): before 260 s (CPU 458),
                                  241 s (424), 244 s (430), 250 s (434); after 242 s (435), 225 s (404),
                                  233 s (417), 230 s (407). In the VM's slow hour (02:40-02:55, the
                                  simulators' compute at 65 % of its usual speed) the before tree took
                                  324-345 s (CPU 562-608): compare passes of one hour only
Profile that chose the changes (the CPU log, per test and file): the pass is CPU-bound (~600 CPU s,
~210-237 s of it in the subprocesses tests start, waited for); under worksteal a module's fixture (a
simulated run of 10-22 s) was set up again on each worker that stole some of its tests
(test_thermal_compare 22 s + 20.7 s at 14:15, but none at 14:20: it depends on the stealing), which
loadfile rules out; the worker-seconds were twice the CPU seconds (tests waiting on subprocesses,
sockets and polls, and on the other users' load), so a fourth worker fills the cores. On an idle
machine the pass cannot go under CPU / 2 cores ~ 300 s without cutting the tests' CPU.
"""

from __future__ import annotations

import argparse
import collections
import os
import resource
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _sample_load(samples: list[float], stop: threading.Event) -> None:
    """The 1-minute load average every 10 s until stop is set."""
    while not stop.wait(10.0):
        samples.append(os.getloadavg()[0])


def worker_ends(log: Path) -> dict[str, tuple[int, float, float]]:
    """worker -> (tests, busy s, its last test's end in s after the pass's first test began)."""
    rows = [line.split("\t") for line in log.read_text(encoding="utf-8").splitlines()]
    t0 = min(float(r[5]) - float(r[3]) for r in rows)
    by: dict[str, list[list[str]]] = collections.defaultdict(list)
    for r in rows:
        by[r[4]].append(r)
    return {w: (len(rs), sum(float(r[3]) for r in rs), max(float(r[5]) for r in rs) - t0)
            for w, rs in sorted(by.items())}


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--workers", type=int, default=4)
    p.add_argument("--dist", default="worksteal")  # make test's
    p.add_argument("--log", type=Path, default=None, help="keep the CPU log here")
    args = p.parse_args()
    log = args.log or Path(tempfile.mkdtemp()) / "cpu.log"
    log.unlink(missing_ok=True)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env.update(CI="true", QT_QPA_PLATFORM="offscreen", GYROBENCH_TEST_CPU_LOG=str(log))
    samples: list[float] = [os.getloadavg()[0]]
    stop = threading.Event()
    threading.Thread(target=_sample_load, args=(samples, stop), daemon=True).start()
    t0 = time.monotonic()
    r = subprocess.run([sys.executable, "-m", "pytest", "-q", "-n", str(args.workers), "--dist", args.dist,
                        "-m", "not serial"], cwd=ROOT, env=env, capture_output=True, text=True)
    wall_s = time.monotonic() - t0
    stop.set()
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    out = log.with_suffix(".out")  # pytest's whole report: a failure's traceback is read there
    out.write_text(r.stdout + r.stderr, encoding="utf-8")
    lines = r.stdout.strip().splitlines() or [""]
    for line in lines:  # what failed or errored (its setup or teardown too), with pytest's one-line reason
        if line.startswith(("FAILED ", "ERROR ")):
            print(line)
    print(lines[-1])
    print(f"-n {args.workers} --dist {args.dist}: wall {wall_s:.0f} s, CPU {kids.ru_utime + kids.ru_stime:.0f} s, "
          f"load average {min(samples):.1f}-{max(samples):.1f} (mean {sum(samples) / len(samples):.1f})")
    for w, (n, busy_s, end_s) in worker_ends(log).items():
        print(f"  {w}: {n} tests, busy {busy_s:.0f} s, last test ended at {end_s:.0f} s")
    print(f"CPU log: {log}; pytest's report: {out}")
    return r.returncode


if __name__ == "__main__":
    raise SystemExit(main())
