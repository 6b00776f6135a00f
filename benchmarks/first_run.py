"""Benchmark: a fresh clone's first compiled-kernel warm-up (what a first `make run` waits for).

Clones REF of this repository into a temporary directory, points NUMBA_CACHE_DIR at an empty
directory (so nothing compiled before is found) and, in a fresh process, calls
`simulators.warm.warm_kernels()` (what a simulated station does before it serves) and the damping
fit's compiled model (`bench.analysis.free_decay_rk`); prints its wall and CPU time (user + system of
the child: less sensitive to other jobs on a shared machine) and when its first line reached stderr.
Then the same again with the cache filled: the cost of every later run.

Run: .venv/bin/python benchmarks/first_run.py [REF ...]   (default: HEAD; several REFs interleave)
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import tempfile
import time

_CHILD = """
import time
t0 = time.perf_counter()
from simulators.warm import warm_kernels
warm_kernels()
from bench.analysis import free_decay_rk  # noqa: F401  (imported for its compiled kernels' load)
print(f"warm-up {time.perf_counter() - t0:.2f} s", flush=True)
"""


def _child(clone: str, cache: str) -> tuple[float, float, float | None]:
    """Wall s, CPU s and seconds to the first stderr line of one warm-up in a fresh process."""
    env = dict(os.environ, PYTHONPATH=clone, NUMBA_CACHE_DIR=cache, PYTHONDONTWRITEBYTECODE="1")
    r0, t0 = resource.getrusage(resource.RUSAGE_CHILDREN), time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-c", _CHILD], cwd=clone, env=env, stderr=subprocess.PIPE,
                            stdout=subprocess.DEVNULL, text=True)
    first = None
    assert proc.stderr is not None
    for _line in proc.stderr:
        if first is None:
            first = time.perf_counter() - t0
    proc.wait()
    wall = time.perf_counter() - t0
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode:
        raise SystemExit(f"warm-up failed in {clone}")
    return wall, r1.ru_utime - r0.ru_utime + r1.ru_stime - r0.ru_stime, first


def main() -> None:
    refs = sys.argv[1:] or ["HEAD"]
    repo = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    for ref in refs:  # interleaved: each ref's cold then warm run before the next ref
        tmp = tempfile.mkdtemp(prefix="gyrobench-first-")
        clone, cache = f"{tmp}/clone", f"{tmp}/numba-cache"
        os.mkdir(cache)
        subprocess.run(["git", "clone", "-q", repo, clone], check=True)
        subprocess.run(["git", "-C", clone, "checkout", "-q", ref], check=True)
        for label in ("fresh clone, empty cache", "second run, cache filled"):
            wall, cpu, first = _child(clone, cache)
            seen = "nothing" if first is None else f"{first:.1f} s"
            print(f"{ref[:12]:12s} {label}: wall {wall:.1f} s, CPU {cpu:.1f} s, first line on stderr: {seen}")


if __name__ == "__main__":
    main()
