"""Where the main thread's wall time goes in a long lockstep record (issues 19 and 20): the run's
world advances (the world's blocks, the FPGA server's stream flush at each advance's end), the
station's link checks at each point of the clock's 0.4 s grid (the table's Modbus status, the front
end's *IDN?, the FPGA link's sync) and the CPU seconds of every thread still alive at the end.
Plain perf_counter wrappers around those calls (no profiler: cProfile's per-call cost would swamp
the 0.1 ms blocks); the run's results are not changed by them.

Run: nice -n 5 .venv/bin/python benchmarks/lockstep_breakdown.py [--procedure cvg-allan]
     [--station sim-hrg-wa] [--set record_s=1200] [--seed 0]

Measured 2026-11-26 on 2 shared cores (load average 2.8-3.7), cvg-allan on sim-hrg-wa, 1200 s record
(1238 simulated s in 6.1-7.3 wall s = 2.8-3.4 sim h / wall min; startup and analysis included):
  per 0.4 s grid point: world.advance 1.19-1.40 ms (of which 8 blocks of 50 ms at 0.12 ms each and the
  stream flush 0.35 ms: a sendall of ~4 frames, most of it waiting for the GIL back from the
  link's reader thread), check_links 0.44-0.59 ms (table status 0.22-0.31 ms, *IDN? ~0.25 ms, FPGA
  sync 0.01-0.03 ms).  Threads' CPU: main 5.2 s, raw-data writer 0.56 s, FPGA reader 0.54 s, the
  Modbus/SCPI request threads 0.15-0.18 s each.
  So the main thread is the bottleneck (about 2 ms per 0.4 simulated s = 18 s per simulated hour
  = 3.3 h/min); the 5 h/min target needs <= 1.33 ms per grid point.  The world's blocks in the
  station cost ~1.8x those of cvg_allan_speed.py (a) (0.068 ms: no front-end model, no other
  threads taking the GIL), the link checks a third of the rest.
After the recorder's flush rule (a second of data flushes once a quarter wall second has passed,
not every few wall ms): the raw-data writer's CPU 0.48-0.56 -> 0.28 s, the stream flush
0.27-0.35 -> 0.06 ms per grid point (the writer no longer holds the GIL when the reader wants it).
Then (2026-11-26; d8058b1 against the tree with the table's status read as one prebuilt Modbus
frame on the client's socket (`probe_status`), the streaming link's sync first and the raw-data
writer woken per batch of blocks; alternately; medians [ranges]):
  6 runs each, load 1.7-6.5, writer batch 16: check_links wall 0.54 [0.40-0.92] -> 0.51 [0.30-1.22]
  ms, main-thread CPU in it 0.26 [0.19-0.34] -> 0.21 [0.15-0.26] ms; table status 0.30 [0.21-0.51]
  -> 0.13 [0.08-0.36] ms wall; process CPU (all threads) per grid point 1.68 [1.25-1.91] -> 1.52
  [1.20-1.83] ms; writer CPU 0.13-0.25 -> 0.06-0.10 s; the quietest runs 3.5 -> 4.0 sim h / wall min.
  3 runs each, load 3.9-5.1, the final tree (writer batch 2, see docs/raw_data.md): check_links
  wall 0.77 [0.70-0.89] -> 0.66 [0.51-1.03] ms, CPU in it 0.33 [0.30-0.34] -> 0.27 [0.23-0.28] ms;
  process CPU per grid point 1.99 [1.84-2.05] -> 1.76 [1.72-1.88] ms; writer CPU 0.20-0.22 ->
  0.15-0.18 s; reader 0.62-0.68 -> 0.57-0.67 s.
  The writer's batched wake-ups were then taken out again (a full disk reached the run later in
  simulated time, by an amount that depends on the load; docs/raw_data.md): the link-check figures
  above are without them.
  So the link checks' own CPU fell by ~1/5, not the 3x asked: their wall time is about the CPU of
  every thread they wait for (main, the FPGA reader's parsing, now seen in the sync, the two
  servers) plus ~4 thread hand-offs under the GIL.  Sending the table's and the front end's
  requests before reading either reply (tried) was no faster in the run and 20% slower in a tight
  loop (the two servers and the main thread then contend for the GIL).
2026-11-26, the world's per-block glue cut (branch `fused`: firmware values cached per register
write, one compiled call for the loops and the stream, pickoff gains in the resonator's kernel,
normal draws in chunks; results bit-identical, benchmarks/sim_identical.py), 1200 s record,
d8058b1 and the branch alternately, twice each, load average 3.6-4.3:
  world block 0.201 / 0.157 ms -> 0.114 / 0.104 ms (1.4-1.9x; ~0.016 ms of it is numba's one-time
  first call, 0.4 s, paid in the run's first block); world.advance per grid point 1.93 / 1.55 ->
  1.19 / 1.00 ms; check_links unchanged (0.6-0.8 ms); the run 1.93 / 2.20 -> 2.72 / 3.01 sim h /
  wall min.  Again after the table's jitter scaling moved into its kernel, load 2.7-3.0: world block
  0.119 / 0.130 -> 0.106 / 0.085 ms, world.advance 1.24 / 1.22 -> 1.10 / 0.97 ms per grid point,
  the run 2.51 / 2.64 -> 2.80 / 2.62 sim h / wall min.  Over the four pairs the block is 1.1-1.9x
  cheaper (the load moves the figures by as much); the link checks are now the main thread's
  largest item.
2026-11-27, hrg-damping on sim-hrg at f0c9d32 (load 1.2-1.5, no CPU steal), timed from after the
station's opening (before, the kernels' warm-up there counted ~100 blocks and ~0.4 s as the run's):
  1108 s in 3.06 s wall; per grid point (2,771 with round trips): the FPGA link's sync 0.19 ms
  (0.03 ms of it this thread's CPU, the rest the reader parsing and delivering the grid point's
  frames), the table's status 0.12 ms, the front end's probe 0.09 ms; the world 0.27 ms an advance
  (2,809 fused runs at 0.21 ms, 1,076 single blocks at 0.09 ms while the table ramps or polls).
  The same checks on an idle station (benchmarks/link_check_floor.py) take 0.001 / 0.05 / 0.05 ms:
  in the run the reader, the writer and the servers' threads share the GIL and two vCPUs that slow
  each other, and every hand-off waits for the other thread's whole piece of work.
  At 14c764f (lockstep's raw data written by the publishing thread, no writer thread beside the
  run): 1108 s in 2.93 s wall, process CPU 3.1 s (3.7 s before); the world 0.23 ms an advance, the
  sync 0.19, the table 0.11, the front end 0.09 ms a grid point; the reader thread 0.56 CPU s (it
  now writes the stream to the recorder's buffer too).
"""

from __future__ import annotations

import argparse
import collections
import os
import tempfile
import threading
import time
from collections.abc import Callable
from typing import Any

_TOTAL_S: dict[str, float] = collections.defaultdict(float)
_CPU_S: dict[str, float] = collections.defaultdict(float)  # the calling thread's CPU seconds in them
_CALLS: collections.Counter[str] = collections.Counter()


def _timed(cls: Any, name: str, key: str) -> None:
    """Replace cls.name (a class's or a module's) by a wrapper adding its wall time to _TOTAL_S[key]."""
    inner: Callable[..., Any] = getattr(cls, name)

    def wrapper(*args: Any, **kwargs: Any) -> Any:
        t0, c0 = time.perf_counter(), time.thread_time()
        try:
            return inner(*args, **kwargs)
        finally:
            _TOTAL_S[key] += time.perf_counter() - t0
            _CPU_S[key] += time.thread_time() - c0
            _CALLS[key] += 1

    setattr(cls, name, wrapper)


def _thread_cpu_s(native_id: int) -> float:
    """User + system CPU seconds of one thread of this process (Linux /proc)."""
    fields = open(f"/proc/self/task/{native_id}/stat").read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--procedure", default="cvg-allan")
    ap.add_argument("--station", default="sim-hrg-wa")
    ap.add_argument("--set", action="append", default=[], metavar="NAME=VALUE")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    from bench.composition.sim_station import SimStation
    from bench.engine import Runner
    from bench.engine.context import GuardedClock
    from bench.station import Station
    from bench.validation import parse_assignment
    from drivers.fpga.link import FpgaLink
    from procedures import find_procedure
    from simulators.fpga.server import FpgaServer
    from simulators.world import World

    sets = dict(parse_assignment(item) for item in args.set) or (
        {"record_s": "1200"} if args.procedure == "cvg-allan" else {})
    import simulators.fused as fused

    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    station = SimStation(args.station, seed=args.seed).open()
    # timed from here: the station's opening drives a throwaway world through every kernel
    # (simulators/warm.py), whose first blocks would otherwise count as the run's
    for cls, name, key in ((World, "advance", "world.advance"), (World, "_run_block", "  world block"),
                           (fused, "run_fused_blocks", "  fused blocks"),
                           (FpgaServer, "_flush_stream", "  stream flush"), (Station, "check_links", "check_links"),
                           (FpgaLink, "sync", "  fpga sync"), (GuardedClock, "sleep", "engine sleeps")):
        _timed(cls, name, key)
    table_cls = type(station.devices["table"])
    _timed(table_cls, "probe_status" if hasattr(table_cls, "probe_status") else "status", "  table status")
    if "frontend" in station.devices:
        fe_cls = type(station.devices["frontend"])
        _timed(fe_cls, "probe" if hasattr(fe_cls, "probe") else "_query", "  frontend probe")
    cpu_s: dict[str, float] = {}
    stop = threading.Event()

    def sample() -> None:
        while not stop.is_set():
            for t in threading.enumerate():
                try:
                    cpu_s[t.name] = _thread_cpu_s(t.native_id or 0)
                except OSError:
                    pass
            time.sleep(0.2)

    threading.Thread(target=sample, name="cpu-sampler", daemon=True).start()
    cpu0 = time.process_time()
    try:
        record = Runner(station, runs_dir=tempfile.mkdtemp(prefix="gyrobench-lockstep-")).run(
            find_procedure(args.procedure), sets)
    finally:
        stop.set()
        station.close()
    print(f"{args.procedure} on {args.station} {sets}: {record.outcome}, {record.simulated_s:.0f} sim s in "
          f"{record.wall_s:.2f} wall s = {record.simulated_s / 3600 / (record.wall_s / 60):.2f} sim h / wall min")
    n_grid = _CALLS["check_links"]
    print(f"process CPU {time.process_time() - cpu0:.2f} s (all threads) = "
          f"{(time.process_time() - cpu0) / n_grid * 1e3:.3f} ms per check_links call")
    print(f"  {'':16s} {'calls':>7s} {'wall s':>8s} {'wall ms':>8s} {'cpu ms':>8s}  (cpu: the calling thread's)")
    for key in _TOTAL_S:
        n = _CALLS[key]
        print(f"  {key:16s} {n:7d} {_TOTAL_S[key]:8.3f} {_TOTAL_S[key] / n * 1e3:8.3f} {_CPU_S[key] / n * 1e3:8.3f}")
    print("threads' CPU s (those alive at the end):")
    for name, s in sorted(cpu_s.items(), key=lambda kv: -kv[1]):
        if s >= 0.05 and name != "cpu-sampler":
            print(f"  {s:7.2f}  {name}")


if __name__ == "__main__":
    main()
