"""Benchmark: where a `make test` parallel pass spends its samples, every process it starts
included (the CLI runs, line stations, Dask workers, the compute pool), by a sampling profiler
(py-spy; issue 36: the profile that chose the suite's cuts).

Runs `pytest -q -n 4 --dist worksteal -m "not serial"` under `py-spy record --subprocesses -f raw`
(PostgreSQL from $GYROBENCH_TEST_PG_URL, CI=true, bytecode written, Qt offscreen: `make test`'s
environment), or reads a raw file such a run wrote (--raw), and prints: the samples per kind of
process; the functions of ours (bench, procedures, simulators, drivers, tests) with the most samples
beneath them (inclusive); and, leaving out samples whose leaf waits (a lock, a socket, a sleep: a
thread that waits is sampled as active by py-spy), each remaining sample charged to the frame of
ours nearest its leaf (where our code spends, in libraries or not). py-spy samples wall time: a
worker that waits for a core is sampled too, so on 2 cores with 4 workers a sample is ~0.5 CPU s
/ rate; compare shares, not seconds. It is not a project dependency: `pip install py-spy`.

Run: .venv/bin/python benchmarks/suite_profile.py [--rate 25] [--out suite.raw] [--raw suite.raw]
     [--top 40] [-- PYTEST_ARGS...]

Measured 2026-11-29 02:50-02:56 (e9d8406, a slow hour of this VM: the same pass took 324-345 s and
562-608 CPU s where it takes 237-260 s and 420-458 CPU s at others), 37,404 samples at 25 Hz, 10,152
of them waiting. What chose this stop's changes (inclusive samples, share of all):
  mems-sweep's model curves (maslov_forced.steady_states: numeric_jacobian 932, forced_rhs 1,426):
      4.1 %  -> a one-call Jacobian and a gathered regressor (bit for bit), ~2x cheaper
  the raw file's compaction at close (recorder.compact):                               2.8 %  -> gzip 1
  tests/conftest.py's full collection after each Qt test:                               2.2 %  -> young only
  forked line stations importing pyvisa_py and scipy.special after the fork:  ~900 of their 2,278
  gyrobench gui importing scipy.signal for one filter (0.7 s a window)     -> exponential_mean
Left as they are (see the stop's note): numba's import and first kernel load in the ~60 processes
that run a simulator (~0.67 s CPU each), the link checks' round trips, WeasyPrint's layout of the
line's PDF certificates, sqlalchemy's import; a rig's per-block advance was 1 % (no fused path for it).
"""

from __future__ import annotations

import argparse
import collections
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: py-spy's raw lines: `process PID:"command";` per process in the chain, then `frame;frame;... COUNT`
_PROCESS = re.compile(r'process (\d+):"((?:[^"\\]|\\.)*)";')
_LINE_NO = re.compile(r":\d+\)$")
OURS = ("bench/", "procedures/", "simulators/", "drivers/", "tests/", "conftest.py")
#: a leaf in one of these waits (a thread py-spy sees as active while it blocks)
WAITING = ("Condition.wait", "Event.wait", "Thread.join", "SocketIO.readinto", "Selector.select", "socket.accept",
           "_read_loop", "_read_exact", "_read_reply", "_recv_line", ".recv", "TCPIPSocketSession.read",
           "Connection.wait", "_QtApi.exec", "Popen.wait", "Popen._wait", "Popen.communicate", "Queue.get",
           "recv_bytes", "_poll", "sleep", "Lock.acquire", "_wait_for_tstate_lock", "select (", "poll (")


def record(raw: Path, rate: int, pytest_args: list[str]) -> int:
    """Run the parallel pass under py-spy, writing its raw samples to `raw`; pytest's exit code."""
    spy = shutil.which("py-spy") or str(Path(sys.executable).with_name("py-spy"))
    if not Path(spy).exists():
        raise SystemExit("suite_profile: py-spy is not installed (pip install py-spy)")
    env = dict(os.environ, CI="true", QT_QPA_PLATFORM="offscreen", PYTHONPATH=str(ROOT))
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    cmd = [spy, "record", "-o", str(raw), "-f", "raw", "-r", str(rate), "--subprocesses", "--nonblocking", "--",
           sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-n", "4", "--dist", "worksteal",
           "-m", "not serial", *pytest_args]
    return subprocess.run(cmd, cwd=ROOT, env=env).returncode


def samples(raw: Path):
    """(process command, frames leaf last, count) of each raw line."""
    with open(raw, encoding="utf-8", errors="replace") as f:
        for line in f:
            stack, _, count = line.rstrip("\n").rpartition(" ")
            if not count.isdigit():
                continue
            procs = _PROCESS.findall(stack)
            frames = [_LINE_NO.sub(")", fr) for fr in _PROCESS.sub("", stack).split(";") if fr]
            yield (procs[-1][1] if procs else "?"), frames, int(count)


def summarise(raw: Path, top: int) -> None:
    kinds: collections.Counter[str] = collections.Counter()
    inclusive: collections.Counter[str] = collections.Counter()
    charged: collections.Counter[str] = collections.Counter()
    total = waiting = 0
    for proc, frames, n in samples(raw):
        total += n
        kinds[" ".join(proc.split()[:4])[:90]] += n
        for fr in set(frames):
            if any(o in fr for o in OURS):
                inclusive[fr] += n
        if not frames or any(w in frames[-1] for w in WAITING):
            waiting += n
            continue
        charged[next((fr for fr in reversed(frames) if any(o in fr for o in OURS)), "(no frame of ours)")] += n
    print(f"{total} samples, {waiting} with a waiting leaf ({100 * waiting / max(total, 1):.0f} %)")
    for title, counter in (("processes", kinds), ("inclusive, our functions", inclusive),
                           ("charged to our frame nearest the leaf (waits left out)", charged)):
        print(f"\n--- {title}")
        for name, n in counter.most_common(top):
            print(f"{n:7d} {100 * n / max(total, 1):5.1f} %  {name[:150]}")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--rate", type=int, default=25, help="samples per second (py-spy's --rate)")
    p.add_argument("--out", default=None, help="keep the raw samples here (default: a temporary file)")
    p.add_argument("--raw", default=None, help="summarise this raw file instead of running the pass")
    p.add_argument("--top", type=int, default=40)
    p.add_argument("pytest_args", nargs="*")
    args = p.parse_args(argv)
    if args.raw:
        summarise(Path(args.raw), args.top)
        return 0
    with tempfile.TemporaryDirectory() as tmp:
        raw = Path(args.out or Path(tmp) / "suite.raw")
        code = record(raw, args.rate, args.pytest_args)
        summarise(raw, args.top)
    return code


if __name__ == "__main__":
    sys.exit(main())
