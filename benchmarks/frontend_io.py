"""Front-end I/O on loopback, the driver beside raw pyvisa-py against the same simulated
instrument in the same run: query rate (driver vs raw `*IDN?`, target within 1.5x) and the
throughput of a 1e5-sample float32 capture block (target >= 150 MB/s; the naive `\\n`-terminated
read is shown for comparison).  The simulator is served from a thread of this process with a
lockstep world (nothing advances it while measuring); `--subprocess` runs it as its own process
(`python -m simulators.frontend`, real time at 1x) instead.  Runs are interleaved (raw, driver,
raw, ...) so machine load hits both alike.
Usage: python benchmarks/frontend_io.py [seconds_per_run] [--subprocess]"""

from __future__ import annotations

import statistics
import subprocess
import sys
import time
from collections.abc import Callable

import numpy as np
import pyvisa

from bench.clock import RealClock, SimClock
from drivers.frontend import ScpiFrontEnd
from simulators.frontend import serve_frontend
from simulators.physics.params import preset
from simulators.world import World

N_SAMPLES = 100_000
RUNS = 5


def rate(fn: Callable[[], object], seconds: float) -> float:
    """Calls per second of fn over about `seconds` of wall time."""
    n, t0 = 0, time.perf_counter()
    while True:
        fn()
        n += 1
        dt = time.perf_counter() - t0
        if dt >= seconds:
            return n / dt


def interleaved_rates(fns: list[Callable[[], object]], seconds: float) -> list[tuple[float, float, float]]:
    """RUNS rounds of every fn in turn; per fn the median (min, max) calls per second."""
    per_fn: list[list[float]] = [[] for _ in fns]
    for _ in range(RUNS):
        for i, fn in enumerate(fns):
            per_fn[i].append(rate(fn, seconds))
    return [(statistics.median(r), min(r), max(r)) for r in per_fn]


def start_server(inprocess: bool):
    """(resource_name, clock, stop) of a simulated front end, in a thread or in its own process."""
    if inprocess:
        world = World(preset("hrg"), seed=1)
        clock = SimClock(world)
        server = serve_frontend(world, seed=2, adc_noise_v=0.05)

        def stop() -> None:
            server.stop()
            clock.close()

        return server.resource_name, clock, stop
    proc = subprocess.Popen(
        [sys.executable, "-m", "simulators.frontend", "--preset", "hrg", "--speed", "1", "--adc-noise-v", "0.05"],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
    )
    resource_name = proc.stdout.readline().strip()

    def stop_proc() -> None:
        proc.stdin.close()
        proc.wait(timeout=10)

    return resource_name, RealClock(), stop_proc


def main(seconds: float = 1.0, inprocess: bool = False) -> None:
    resource_name, clock, stop = start_server(inprocess)
    rm = pyvisa.ResourceManager("@py")
    raw = rm.open_resource(resource_name, read_termination="\n", write_termination="\n", timeout=5000)
    raw.chunk_size = 1 << 20
    fe = ScpiFrontEnd(resource_name, clock=clock, resource_manager=rm).connect()
    try:
        fe.set_drive(1, amplitude_v=0.5, frequency_hz=5500.0, output_on=True)
        fe.sample_rate_hz = 1e6
        t0 = time.perf_counter()
        fe.capture(1, N_SAMPLES)
        t_capture = time.perf_counter() - t0
        n_bytes = 4 * N_SAMPLES

        def raw_block_exact() -> bytes:
            raw.write("FETC:CAPT1?")
            with raw.read_termination_context(None):
                head = raw.read_bytes(2)
                count = int(raw.read_bytes(int(head[1:2])))
                return raw.read_bytes(count + 1, chunk_size=count + 1)

        def raw_block_naive() -> object:
            return raw.query_binary_values("FETC:CAPT1?", datatype="f", container=np.array)

        names = ["raw *IDN?", "driver idn", "driver lockin_all()", "driver ch1.amplitude_v (get)",
                 "driver ch1.amplitude_v = (set + SYST:ERR?)"]
        fns = [lambda: raw.query("*IDN?"), lambda: fe.idn, fe.lockin_all, lambda: fe.ch1.amplitude_v,
               lambda: setattr(fe.ch1, "amplitude_v", 0.5)]
        rows = [(n, r, "q/s") for n, r in zip(names, interleaved_rates(fns, seconds), strict=True)]
        mb = n_bytes / 1e6
        block_names = ["raw block, exact byte counts", "driver fetch_capture(1)",
                       "raw block, query_binary_values + \\n termination"]
        block_fns = [raw_block_exact, lambda: fe.fetch_capture(1), raw_block_naive]
        blocks = list(zip(block_names, interleaved_rates(block_fns, seconds), strict=True))
        where = "in-process thread" if inprocess else "own process"
        print(f"front end on loopback, simulator in its {where} ({RUNS} interleaved runs of {seconds:g} s, "
              "median (min-max))")
        for name, (med, lo, hi), unit in rows:
            print(f"  {name:46s} {med:8.0f} ({lo:.0f}-{hi:.0f}) {unit}")
        idn_raw = rows[0][1][0]
        for name, (med, _, _), _ in rows[1:4]:
            print(f"  ratio raw *IDN? / {name:28s} {idn_raw / med:5.2f}x  (target <= 1.5x)")
        print(f"  1e5-sample capture block: {n_bytes} bytes")
        for name, (med, lo, hi) in blocks:
            print(f"  {name:46s} {med * mb:8.1f} ({lo * mb:.1f}-{hi * mb:.1f}) MB/s")
        print(f"  full capture() incl. its 0.1 s acquisition ({where}): {t_capture * 1e3:.1f} ms wall")
    finally:
        fe.close()
        raw.close()
        rm.close()
        stop()


if __name__ == "__main__":
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    main(float(args[0]) if args else 1.0, inprocess="--subprocess" not in sys.argv)
