"""Several gyros on one table: a line sequence (default eol-hrg) on N = 1, 2, 4, 8 simulated HRGs
at once (a station with N slots like sim-hrg-4: one table, one switched front end, an FPGA a
slot), lockstep.  Per N: units per hour in bench time (what a real line gets: the table's time
shared), and the wall and CPU seconds per unit of the simulation (this process and its compute
workers).  Every unit's outcome is printed so a wrong batch is seen, not only a fast one.
Run: nice -n 5 .venv/bin/python benchmarks/line_batch_speed.py [--sequence eol-hrg] [--n 1 2 4 8]
"""

from __future__ import annotations

import argparse
import resource
import sys
import tempfile
import time
from pathlib import Path

SLOT = '[slots.{n}.fpga]\ndriver = "fpga-link"\n'
HEAD = """[station]
id = "sim-hrg-{n}"
kind = "hrg"
[simulation]
preset = "hrg"
seed = {seed}
[devices.table]
driver = "modbus-table"
max_rate_dps = 1000.0
max_accel_dps2 = 500.0
[devices.frontend]
driver = "scpi-frontend"
"""


class _Yes:
    def confirm(self, question: str) -> bool:
        return True

    def show_outcome(self, *args) -> None:
        pass


def _cpu_s() -> float:
    me, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


def one_batch(n: int, sequence: str, seed: int, folder: Path) -> dict:
    """The sequence on n slots at once: bench seconds, wall and CPU seconds, outcomes."""
    from bench.composition import load_station
    from bench.line.batch_run import run_batch_attempt
    from bench.line.limits import load_limits
    from bench.line.run import LineContext
    from bench.line.sequence import load_sequence

    station_file = folder / f"sim-hrg-{n}.toml"
    station_file.write_text(HEAD.format(n=n, seed=seed) + "".join(SLOT.format(n=k) for k in range(1, n + 1)))
    seq = load_sequence(sequence)
    ctx = LineContext(seq, load_limits(seq.limits), f"sim-hrg-{n}", "bench", folder / f"runs{n}")
    station = load_station(station_file).open()
    try:
        t0_bench, t0_wall, t0_cpu = station.base_clock.now(), time.monotonic(), _cpu_s()
        records = run_batch_attempt(ctx, station, {k: f"B{n}-{k}" for k in range(1, n + 1)}, _Yes())
        bench_s = station.base_clock.now() - t0_bench  # the table's time, its rests included
        wall_s, cpu_s = time.monotonic() - t0_wall, _cpu_s() - t0_cpu
    finally:
        station.close()
    return {"n": n, "bench_s": bench_s, "wall_s": wall_s, "cpu_s": cpu_s,
            "outcomes": [r["outcome"] for r in records]}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sequence", default="eol-hrg")
    ap.add_argument("--n", type=int, nargs="+", default=[1, 2, 4, 8])
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for n in args.n:
            row = one_batch(n, args.sequence, args.seed, Path(tmp))
            rows.append(row)
            print(f"N={n}: bench {row['bench_s']:.0f} s, wall {row['wall_s']:.1f} s, CPU {row['cpu_s']:.1f} s; "
                  f"{' '.join(row['outcomes'])}", flush=True)
    base = rows[0]
    print(f"\n{args.sequence}, lockstep, load {' '.join(f'{x:.1f}' for x in __import__('os').getloadavg())}")
    print("| N | units/h (bench) | x N=" + str(base["n"]) + " | wall s/unit | x | CPU s/unit | x |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        uph = 3600.0 * r["n"] / r["bench_s"]
        uph0 = 3600.0 * base["n"] / base["bench_s"]
        w, c = r["wall_s"] / r["n"], r["cpu_s"] / r["n"]
        w0, c0 = base["wall_s"] / base["n"], base["cpu_s"] / base["n"]
        print(f"| {r['n']} | {uph:.1f} | {uph / uph0:.2f} | {w:.2f} | {w / w0:.2f} | {c:.2f} | {c / c0:.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
