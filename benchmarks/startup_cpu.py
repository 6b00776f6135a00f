"""Benchmark: the CPU a `gyrobench` process pays, command by command, this tree against another
(issue 36: the suite starts ~200 such processes; `run hrg-damping` <= 1.5x the run's own wall).

Each round runs, in fresh processes, `gyrobench --help`, `run table-spin --set hold_s=0.1`, `run
hrg-damping` (seed 0, record_s default), `runs`, `report RUN` (HTML of that hrg-damping run), `list`
and a line station (`python -m bench.line.stations`, one unit of ci-spin, --no-pdf, on a line
database made by a first station) once per tree, the trees alternating (interleaved, so a busy
machine weighs on both alike), and prints per command the median CPU (user + system of the process
and the children it waited for: what a shared 2-core machine pays) and wall. Both trees use this
checkout's compiled-kernel cache (NUMBA_CACHE_DIR) and a bytecode cache of their own
(PYTHONPYCACHEPREFIX, as `make test` writes bytecode), so neither compiles. The `run`s write into a
results store made by a first run (the stores users have), so the store's opening is the everyday
one.

Run: .venv/bin/python benchmarks/startup_cpu.py --against TREE [--rounds 5]

Measured 2026-11-28 12:25-12:29 (load average 4.5-6 on the 2 shared cores), /work/main at 0caed6a
(before) against wave3e/startup, 5 rounds interleaved, medians, CPU s (wall s):
  --help                        0.08 (0.09) -> 0.08 (0.09)
  run table-spin hold_s=0.1     2.21 (2.59) -> 1.40 (1.39)   (no scipy.stats; no alembic)
  run hrg-damping               4.14 (6.80) -> 3.44 (4.12)   (no alembic)
  runs                          0.44 (0.90) -> 0.27 (0.54)   (no alembic)
  report RUN (HTML)             2.19 (1.88) -> 2.14 (2.77)   (untouched: matplotlib's figures)
  hrg-damping command wall / the run's own wall: 1.74 -> 1.49 (the run's wall follows the load)
Then with the fpga subcommand's modules imported when it runs (12:37, 7 rounds, CPU medians):
`--help` 0.07 -> 0.05 s, `runs` 0.38 -> 0.24 s.
Profile that chose each change (-X importtime, cProfile of `main`, the phases of
benchmarks/run_end_to_end.py), a table-spin run: table-spin's analysis imported scipy.stats for one
t quantile (~1.0 s wall under load, ~0.4-0.8 s CPU) -> scipy.special.stdtrit, what stats.t.ppf
calls (bit for bit: tests/test_table_spin_analysis.py); the results store imported alembic
(~0.3 s CPU) and loaded its migration scripts on every opening -> one query of alembic's version
table against the head read from the migration files; alembic only when a migration is due.
Left as they are: numba's import (~0.3 s CPU) and its first cached-kernel load (~0.4-0.5 s CPU:
numba's typing and lowering registries, numba.np.arraymath importing scipy.linalg for BLAS), a
fixed cost of any process that runs a kernel; loading all the simulators' cached kernels and
driving the warm-up worlds after that costs ~0.09 s CPU (simulators/warm.py), so loading only a
run's kernels, lazily, would gain <0.1 s and give up the guarantee that a run loads no kernel
under the world lock (tests/test_warm_kernels.py).
Then (2026-11-28 15:14-15:20, load average 5-9): scipy.linalg's package no longer imported by numba's BLAS
check; the figures and the profile that chose it are in benchmarks/run_end_to_end.py's docstring.
Then (2026-11-28 17:30-17:55, load average 3-9; `python -X importtime` of each command, and which of
pyvisa, pymodbus, numba, alembic, h5py its process had in sys.modules), 8d98427 against wave3h/startup,
CPU medians: this script, 5 rounds: `list` 0.48 -> 0.22 s (no numba, pyvisa, pymodbus: the drivers'
packages import their drivers on first use, fpga-link's entry takes the output modes from
drivers.fpga.stream, hrg-selfcal the TRIM_EN bits when it runs); by hand, interleaved: a line station
(one unit, the line database at the head) 2.15 -> 1.96 s (6 each: no alembic), `show RUN` 0.53 ->
0.36 s (3 each: no h5py), `sim --duration-s 1` 0.98 -> 0.81 s (4 each: the simulators' protocol
modules without pymodbus, pyserial, pyvisa); `run hrg-damping` 3.38 -> 3.33 s (6 each) and `run
table-spin` (1.30 -> 1.19 s here, noise) unchanged: every library they import they use.  Left as it
is: table-spin's t quantile (scipy.special.stdtrit; importing scipy.special costs ~0.18 s of CPU, most
of it scipy's array-API layer cloning numpy, which imports numpy.f2py and numpy.testing; no other
import path gives the same ufunc: scipy.special.cython_special imports the package too).
Then (2026-11-28 21:25-21:30, load average ~5; wave3j/startup, no code changed): a line station
(one unit of ci-spin, --no-pdf, sqlite line database at the head) profiled again with -X importtime
and cProfile of its main. Profile with bytecode written, as `make test` does (env -u
PYTHONDONTWRITEBYTECODE): 1.53-1.68 s CPU (3 runs); without bytecode 1.8-2.0 s, of it ~0.43 s
compiling our own 150 modules (a profile taken under PYTHONDONTWRITEBYTECODE overstates import costs,
e.g. pydoc under scipy._lib._docscrape: 77 ms there, 3 ms with bytecode). Import wall under that load:
numba 385 ms (numba.np.linalg 89 ms self, loaded by numba's registries), sqlalchemy 254 ms (the line
database and the results store), scipy.special 205 ms (table-spin's t quantile, as above), h5py 113 ms
(bench.recorder: the station writes the unit's raw .h5), every procedure and bench.analysis module
61 ms self (bench.line.limits.declared_measurements imports all procedures to check the limits file's
measurement names, procedures and units), jinja2 18 ms (the HTML certificate is written under --no-pdf
too), pyvisa_py through pyvisa's open_visa_library (the @py backend the front end opens). Each is
used by the unit; left as they are. A candidate not taken: checking a limits file against the
sequence's own procedures only (~35-60 ms a station) would reject a limit on a measurement only
other procedures declare and check units against fewer procedures: a change of behaviour.
"""

from __future__ import annotations

import os
import re
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _env(tree: Path, tmp: str) -> dict[str, str]:
    cache = os.environ.get("NUMBA_CACHE_DIR") or str(ROOT / ".kernel_cache")
    env = dict(os.environ, PYTHONPATH=str(tree), NUMBA_CACHE_DIR=cache,
               PYTHONPYCACHEPREFIX=f"{tmp}/pycache-{tree.name}")
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    return env


def timed(args: list[str], tree: Path, cwd: str, tmp: str, module: str = "bench.cli") -> tuple[float, float, str]:
    """(CPU s, wall s, stdout) of `python -m MODULE ARGS` (`gyrobench ARGS`) in a fresh process."""
    t0, r0 = time.perf_counter(), resource.getrusage(resource.RUSAGE_CHILDREN)
    out = subprocess.run([sys.executable, "-m", module, *args], check=True, capture_output=True, text=True,
                         env=_env(tree, tmp), cwd=cwd).stdout
    wall = time.perf_counter() - t0
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r1.ru_utime - r0.ru_utime + r1.ru_stime - r0.ru_stime, wall, out


def one_round(tree: Path, tmp: str, work: str) -> dict[str, tuple[float, float]]:
    """Each command once in `work` (its runs directory and results store kept from round to round)."""
    store = ["--runs-dir", f"{work}/runs", "--results", f"{work}/results.sqlite"]
    got: dict[str, tuple[float, float]] = {}
    cpu, wall, _ = timed(["--help"], tree, work, tmp)
    got["--help"] = (cpu, wall)
    cpu, wall, _ = timed(["run", "table-spin", "--set", "hold_s=0.1", *store], tree, work, tmp)
    got["run table-spin hold_s=0.1"] = (cpu, wall)
    cpu, wall, out = timed(["run", "hrg-damping", "--seed", "0", "--json", *store], tree, work, tmp)
    got["run hrg-damping"] = (cpu, wall)
    got["  (its run's own wall)"] = (float("nan"), float(re.search(r'"wall_s": ([0-9.]+)', out).group(1)))
    run_id = re.search(r'"run_id": "([^"]+)"', out).group(1)
    cpu, wall, _ = timed(["runs", "--results", f"{work}/results.sqlite"], tree, work, tmp)
    got["runs"] = (cpu, wall)
    cpu, wall, _ = timed(["report", run_id, "--results", f"{work}/results.sqlite"], tree, work, tmp)
    got["report RUN (HTML)"] = (cpu, wall)
    cpu, wall, _ = timed(["list"], tree, work, tmp)
    got["list"] = (cpu, wall)
    # one unit of ci-spin, as each of tests/test_line_db.py's eight stations runs (the database at the head)
    station = [f"sqlite:///{work}/line.sqlite", f"{work}/line", str(len(list(Path(work).glob("line/st*")))), "1",
               "--no-pdf"]
    cpu, wall, _ = timed(station, tree, work, tmp, module="bench.line.stations")
    got["line station, 1 unit"] = (cpu, wall)
    return got


def main() -> None:
    args = sys.argv[1:]
    before = Path(args[args.index("--against") + 1]).resolve()
    rounds = int(args[args.index("--rounds") + 1]) if "--rounds" in args else 5
    trees = [("before", before), ("after", ROOT)]
    tmp = tempfile.mkdtemp(prefix="gyrobench-startup-")
    works = {label: tempfile.mkdtemp(dir=tmp) for label, _ in trees}
    for label, tree in trees:  # untimed: bytecode written, the results store and the line database made
        timed(["run", "table-spin", "--set", "hold_s=0.1", "--runs-dir", f"{works[label]}/runs",
               "--results", f"{works[label]}/results.sqlite"], tree, works[label], tmp)
        timed([f"sqlite:///{works[label]}/line.sqlite", f"{works[label]}/line", "0", "1", "--no-pdf"], tree,
              works[label], tmp, module="bench.line.stations")
    rows: dict[str, list[dict[str, tuple[float, float]]]] = {label: [] for label, _ in trees}
    for _ in range(rounds):
        for label, tree in trees:
            rows[label].append(one_round(tree, tmp, works[label]))
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores; {rounds} rounds, interleaved; "
          "medians: CPU s (wall s), before -> after")
    for what in rows["before"][0]:
        med = {label: [statistics.median(r[what][i] for r in rows[label]) for i in (0, 1)] for label, _ in trees}
        b, a = med["before"], med["after"]
        print(f"  {what:28s} {b[0]:5.2f} ({b[1]:5.2f}) -> {a[0]:5.2f} ({a[1]:5.2f})")
    for label, _ in trees:
        ratios = [r["run hrg-damping"][1] / r["  (its run's own wall)"][1] for r in rows[label]]
        print(f"  {label}: hrg-damping command wall / run's wall, median {statistics.median(ratios):.2f}")


if __name__ == "__main__":
    main()
