"""Simulated seconds per wall second (x real time) of the simulated devices (issue 14, item 6):
  (a) the free-decay World alone: the resonator, a 300 s decay at 1 kHz, case at 500 deg/s;
  (b) the in-process device world: FPGA firmware (drive, AGC, PLL, quadrature loop on, stream
      at 100 Hz, frames encoded) and table mechanics (500 deg/s) on one World, no transports;
  (c) the whole `hrg-damping` procedure on `sim-hrg` (real drivers over loopback, lockstep).
Targets: (b) >= 2000x, (c) >= 1000x on a quiet machine.  The cases run interleaved (a, b, c,
a, b, c, ...) so a load that changes over time hits each alike; medians and ratios are printed,
per wall second (the target) and per CPU second of this process (less sensitive to other load).

Run: .venv/bin/python benchmarks/sim_world_speed.py [--only a,b,c] [--repeat 3] [--device-s 120]

Measured 2026-11-23 on 2 shared cores, load average 8-10 from other jobs, 4 interleaved rounds
(the tree before issue 14 item 6 against after the compiled kernels; medians, x real time per wall s / per CPU s):
  (a) free-decay World        1,375 / 4,750   ->  3,100 /  9,450
  (b) device world               34 /   115   ->    650 /  2,050  (another round, load 8-10: 1,770 / 2,700)
  (c) hrg-damping, 1108 s        63 /   113   ->    108 /    216
Then (same day, a quiet moment, load 0.7-2.0; this script run on d4c1594 and on the tree after
the stream/grid/worker changes, alternately, twice each, medians of 3 rounds):
  (a)  12,868 / 12,883  ->  13,059 / 13,117            (per wall s, two processes each; ~13,000 per CPU s both)
  (b)   2,911 /  3,016  ->   3,098 /  3,049            (~3,000 per CPU s both)
  (c)       302 /    237  ->     372 /    319  (the script of d4c1594, which imported the simulators
        at its top, so `ctx.compute`'s worker paid numba's import: ~0.4 s a run)
  (c)       339 /    436  ->     453 /    410  (this script on both trees; per CPU s 302 / 438 -> 453 / 404)
Then (2026-11-26, load average 7-10 from other jobs; this script run on 2922767 and on the tree
with its own Modbus server, the front end on the threaded line server and the link checks' rows
recorded in blocks, alternately, 3 times each, each the median of 3 runs; per wall s / per CPU s):
  (a)   3,471 / 8,260   2,443 / 5,772   3,141 / 7,878  ->  1,457 / 7,386   2,129 / 5,706   3,917 / 8,291
  (b)     714 / 1,492     214 / 1,053     651 / 1,714  ->    736 / 1,487     473 / 1,195   1,070 / 1,752
  (c)      79 /   169     127 /   192     147 /   231  ->    193 /   258     183 /   281     236 /   294
  (c) medians of the three: 127 / 192 -> 193 / 281 (x1.52 per wall s, x1.46 per CPU s); (a), (b)
  unchanged within the load's noise (their code did not change).  Again on the final tree (the
  link checks' role order also kept), load 6-10:
  (c)     161 /   233     221 /   222     219 /   209  ->    301 /   293     279 /   305     301 /   267
  medians 219 / 222 -> 301 / 293 (x1.37 per wall s, x1.32 per CPU s); (a) and (b) came out 1.1-1.4x
  faster "after" this time and slower the time before: the load's noise, not the code.  Per thread (CPU s a run, same
  load): the Modbus server 0.6-1.0 -> 0.15-0.25; main thread ~2.7 (World.advance 1.1, link checks
  0.7), FPGA link reader ~0.5-0.7, front-end server ~0.2-0.3, writer + recorder ~0.5.
  A third set at a quieter moment (load 1.2-2.7; 2922767 against eb37d10, alternately, twice each,
  each the median of 3 runs; per wall s / per CPU s):
  (c)     156 /   177     201 /   186  ->    353 /   316     212 /   209
  (a) 3,362-6,579 / 6,597-7,082 -> 5,850-7,760 / 5,873-7,911; (b) 1,029-1,407 / 1,172-1,409 ->
  1,191-1,421 / 1,192-1,734: even at load ~2 both cores were busy (the quiet figures of 2026-11-23
  were ~13,000 and ~3,000), so none of the three sets is a quiet machine's.
(c) is still far from 1000x, which allows 1.1 s of wall (one core) for the 1108 s run.  Where a
run's CPU goes now (thread CPU clocks, load 6-10, 2026-11-26; ~3.8-4.5 CPU s a run in all):
  main thread ~2.5-3.0: World.advance 1.1-1.4 (13,872 blocks of the World, FPGA firmware with its
    ~300 k stream frames at 1 kHz, table mechanics, the front end's lock-in: 80-100 us a block);
    link checks 0.7-0.9 (2,771, one per 0.4 s grid point: the table's Modbus status read 0.33 s,
    ~120 us client side in pymodbus; the front end's *IDN? 0.30 s, ~110 us in pyvisa-py; the FPGA
    link's sync 0.07 s); engine checkpoints, clock and procedure ~0.7;
  FPGA link reader 0.45-0.7 (parsing and delivering the frames in ~3,600 pieces);
  writer thread and HDF5 recorder ~0.5 (925 flushes: one each simulated second, the raw file's
    contract, docs/raw_data.md);
  the simulators' servers: Modbus 0.15-0.25, front end 0.2-0.3.
The World alone takes the whole 1.1 s budget, and the checks that find a fault within 0.5 s
(two stock-client round trips per 0.4 s) another 0.65 s of client time.  The compute worker (fork
+ fit, ~0.1-0.3 s wall) is not in the per-CPU-s figures (another process); the raw file's
compaction after the run (gzip, ~0.3-0.8 s) is in them but not in the wall figures (the run's
wall time is taken before it).
Then (2026-11-26, load 2.3-3.5; d8058b1 against the tree with the table's lean status probe, the
streaming link's sync first and the writer woken per batch; alternately, twice each, medians of 3
runs; per wall s / per CPU s):
  (c)     274 /   230     232 /   202  ->    273 /   247     299 /   268   (x1.1 per CPU s)
  The link checks' client side went from ~0.26 to ~0.21 ms of main-thread CPU per grid point and
  the writer thread's CPU (woken per 2 blocks; these runs had 16) from 0.2 to 0.07-0.15 s a run;
  the round trips themselves are thread hand-offs under the GIL (benchmarks/lockstep_breakdown.py).
  The writer's batched wake-ups were taken out again at the merge (docs/raw_data.md), so part of
  this x1.1 (the writer's ~0.1 CPU s a run) is not in main.
2026-11-26, the world's per-block glue cut (branch `fused`; seeded results bit-identical, checked
with benchmarks/sim_identical.py), d8058b1 against the branch, alternately, twice each, medians of 3
(per wall s / per CPU s), load average 2.7-4.0:
  (a)  4,754 / 5,425   4,327 / 5,150  ->  5,125 / 5,135   5,182 / 5,229   (unchanged: no loops)
  (b)    987 / 1,063     783 / 1,170  ->  1,061 / 1,104   1,075 / 1,076   (~1.05x: this world has no
       noise model and no pickoff noise, where most of the saving is; the table at rate, the
       firmware and the frame encoder's glue remain: ~45 us a block)
  (c)    283 /   261     237 /   226  ->    308 /   312     302 /   291   (1.1-1.3x)
  The static whole-angle world of benchmarks/cvg_allan_speed.py (noise on) gains more: its
  blocks 46-68 -> 31-46 CPU us.
2026-11-27, the world's fused blocks (simulators/fused.py: K loop periods in one compiled call,
bit-identical: tests/test_world_fused.py, benchmarks/sim_identical.py) and the front end's link
check on pyvisa-py's socket; ffbf24f (PYTHONPATH set to its tree) then the new tree, one run of 3
rounds each, nothing else running (load average 0.9-1.0), medians (per wall s / per CPU s):
  (a)  5,372 / 5,372  ->  5,009 / 5,009   (unchanged: no loops, no fused path)
  (b)  1,497 / 1,497  ->  3,469 / 3,469   (x2.3: the target 2,000x met)
  (c)    248 /   219  ->    278 /   251   (x1.12-1.15: far from 1,000x)
  hrg-damping now spends its wall time (benchmarks/lockstep_breakdown.py, 4.3 s for 1,108 s):
  link checks 2.0 s (4,592 checks, 2,771 with round trips: the FPGA link's sync 0.95 s, most of it
  waiting for the reader thread to parse and deliver the 1 kHz stream, the table's status 0.43 s,
  the front end's probe 0.35 s), the world 1.5 s (fused calls 0.7 s for 2,809 runs of blocks;
  1,076 blocks one by one while the table ramps or the front end drives, 0.48 s with numba's
  one-time loads of ~0.4 s), the rest the procedure and engine.  The reader thread 0.8 CPU s and
  the writer 0.3 CPU s contend for the GIL with them.  1,000x needs the whole run in 1.1 s: the
  link checks alone exceed it, so the next lever is not in the simulated devices.
  Then the table's ramp and position motion as a compiled step (bit-identical) and the kernels
  loaded when the simulated station opens (simulators/warm.py: ~0.4 s of numba's cache loads that
  were in the run's first blocks now come before the run, outside this script's timing), load 0.8-0.9:
  (a) 4,529-6,542x, (b) 3,141-5,058x (the load's noise), (c) 333x median (310-385x), 274x per CPU s.
  (c)'s 278 -> 333x is partly the table's step (a ramping block's motion: ~200 us of Python loop
  -> ~4 us) and partly the loads moved out of the run (not told apart here); the whole 1,108 s run
  now takes ~3.3-3.9 s wall.
2026-11-27 (later), the compute worker started warm (the fit step 0.24-0.32 -> 0.10-0.12 s wall),
the table's waits polling with the lean status read, the FPGA link's reads checked in one compiled
pass (reader CPU a read 66-84 -> 28-30 us), all bit-identical (benchmarks/sim_identical.py); 26daa52
(PYTHONPATH on its tree) and the new tree alternately, twice each, 3 rounds, no CPU steal from the
host (/proc/stat), load 1.1-1.3:
  (c)  304 / 261   328 / 285  ->  351 / 289   355 / 309   (x1.08-1.15)
  and in fresh processes, one run each, the two trees alternately, 7 each (load 0.5-1.4): median
  302 -> 356x per wall s (257-365 -> 303-412), 263 -> 305x per CPU s.  The whole run: 3.1-3.6 s.
  On this machine the two vCPUs slow each other: a compiled CRC of 40 frames takes 5 us alone and
  10 us with the other vCPU busy, and the host's CPU steal (the 8th field of /proc/stat's cpu line)
  took a run to 102-158x during this stop while the load average stayed ~1: speed figures need the
  steal read beside them.  Then the raw data written in lockstep by the thread that publishes them
  (bench.writer: no writer thread working beside the run), 005583d against it alternately, 6 runs
  each in fresh processes, no steal: median 472 -> 578x (per CPU s 404 -> 471).  The whole stop,
  26daa52 against 14c764f, 6 each alternately, no steal, load 0.7-1.4: median 367 -> 521x per wall s
  (357-381 -> 426-597x), 332 -> 435x per CPU s; this script on 14c764f: (a) 5,150x, (b) 3,522x,
  (c) 434x (412-437x).  Why (c) stays far from 1000x: benchmarks/link_check_floor.py and
  benchmarks/lockstep_breakdown.py.
2026-11-28 (issue 36: report, command end to end; the link checks untouched, the concurrent form
measured and not adopted: benchmarks/link_checks_concurrent.py), this tree, load average 0.8-0.9,
medians of 3 (per wall s / per CPU s):
  (a) 6,291 / 6,306   (b) 4,599 / 4,599   (c) 376 / 315
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time

# the simulators are imported in the functions: `ctx.compute`'s worker imports this module as its
# __main__, and should not pay numba's import and kernel loading there (as the `gyrobench` CLI does not)


class _Spin:
    """The case turning at a constant rate (no table mechanics): the free-decay world's only device."""

    def __init__(self, rate_dps: float) -> None:
        self.rate_dps = rate_dps

    def before_block(self, world, t_s, n, dt_s):
        world.case_rate_dps = self.rate_dps

    def after_block(self, world, block):
        pass


def free_decay_world(duration_s: float = 300.0) -> tuple[float, float]:
    """(a) x real time of the World alone over a free decay."""
    from bench.analysis.slow_model import state_from_elements
    from simulators.physics.params import preset
    from simulators.world import World

    world = World(preset("hrg"), seed=1, sample_period_s=1e-3)
    world.resonator.set_state(state_from_elements(1.0, 0.0, 0.0))
    world.attach(_Spin(500.0))
    t0, c0 = time.perf_counter(), time.process_time()
    world.advance(duration_s)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    assert world.sample_index == round(duration_s * 1000)
    return duration_s / wall, duration_s / cpu


def device_world(duration_s: float = 120.0, seed: int = 1) -> tuple[float, float]:
    """(b) x real time of the World with the FPGA firmware and the table attached, loops on."""
    from bench.analysis.slow_model import state_from_elements
    from drivers.fpga import protocol as p
    from drivers.rate_table import modbus_protocol as mp
    from simulators.fpga.firmware import FpgaFirmware
    from simulators.physics.params import preset
    from simulators.rate_table.mechanics import TableMechanics
    from simulators.world import World

    params = preset("hrg")
    world = World(params, seed=seed, sample_period_s=1e-3)
    world.resonator.set_state(state_from_elements(1.0, 0.0, 0.0))
    fw = FpgaFirmware(world)
    frames = [0]

    def sink(data: bytes, n: int) -> None:
        frames[0] += n

    fw.sink = sink
    world.attach(fw)
    table = TableMechanics(seed=seed, watchdog_s=0.0)
    world.attach(table)
    regs = {"REF_FREQ_HZ": params.f0_hz, "AGC_SETPOINT": 1.0, "STREAM_DECIMATION": 10}
    for name, value in regs.items():
        fw.write(p.register(name), value)
    fw.write(p.register("CTRL"), p.DRIVE_EN | p.AGC_EN | p.PLL_EN | p.QUAD_EN | p.STREAM_EN)
    table.set_enabled(True)
    table.command(mp.MODE_RATE, 500.0, 0.0, 1000.0)
    world.advance(2.0)  # the table reaches its rate; not timed
    assert table.settled() and abs(table.rate_dps - 500.0) < 1e-6
    f0 = frames[0]
    t0, c0 = time.perf_counter(), time.process_time()
    world.advance(duration_s)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    assert frames[0] - f0 == round(duration_s * 100), frames[0] - f0
    return duration_s / wall, duration_s / cpu


def damping_procedure(runs_dir: str, seed: int = 0) -> tuple[float, float]:
    """(c) x real time of the whole hrg-damping procedure (its defaults) on sim-hrg."""
    from bench.composition.sim_station import SimStation
    from bench.engine import Runner
    from procedures.hrg_damping import HrgDamping

    station = SimStation("sim-hrg", seed=seed).open()
    try:
        c0 = time.process_time()
        record = Runner(station, runs_dir=runs_dir).run(HrgDamping, {})
        cpu = time.process_time() - c0
    finally:
        station.close()
    assert record.outcome in ("PASS", "COMPLETE"), record.outcome
    return record.simulated_s / record.wall_s, record.simulated_s / cpu


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default="a,b,c", help="cases to run, comma-separated (a, b, c)")
    ap.add_argument("--repeat", type=int, default=3, help="runs of each case (interleaved)")
    ap.add_argument("--device-s", type=float, default=120.0, help="simulated seconds of case (b)")
    args = ap.parse_args()
    cases = [c.strip() for c in args.only.split(",") if c.strip()]
    bad = set(cases) - {"a", "b", "c"}
    if bad:
        ap.error(f"--only: unknown cases {sorted(bad)} (expected a, b, c)")
    tmp = tempfile.mkdtemp(prefix="gyrobench-simspeed-")
    runs = {
        "a": lambda: free_decay_world(),
        "b": lambda: device_world(args.device_s),
        "c": lambda: damping_procedure(tmp),
    }
    names = {
        "a": "(a) free-decay World (resonator, 300 s at 1 kHz)",
        "b": "(b) device world (FPGA loops + stream 100 Hz, table 500 deg/s)",
        "c": "(c) hrg-damping over the real transports",
    }
    t0 = time.perf_counter()
    free_decay_world(1.0)  # warm-up, untimed: imports, first calls (loading numba's compiled kernels)
    device_world(0.5)  # (c)'s station loads its own kernels when it opens (simulators/warm.py)
    print(f"warm-up (first calls in this process): {time.perf_counter() - t0:.2f} s")
    load0 = os.getloadavg()[0]
    print(f"load average {load0:.1f} on {os.cpu_count()} cores; {args.repeat} interleaved runs of {','.join(cases)}")
    speeds: dict[str, list[float]] = {c: [] for c in cases}
    cpu_speeds: dict[str, list[float]] = {c: [] for c in cases}
    for r in range(args.repeat):
        for c in cases:
            wall, cpu = runs[c]()
            speeds[c].append(wall)
            cpu_speeds[c].append(cpu)
            print(f"  run {r + 1} {c}: {wall:,.0f}x per wall s, {cpu:,.0f}x per CPU s", flush=True)
    print(f"load average at the end {os.getloadavg()[0]:.1f}")
    med = {c: statistics.median(v) for c, v in speeds.items()}
    med_cpu = {c: statistics.median(v) for c, v in cpu_speeds.items()}
    for c in cases:
        v = speeds[c]
        print(f"{names[c]:66s} median {med[c]:8,.0f}x real time (min {min(v):,.0f}x, max {max(v):,.0f}x); "
              f"{med_cpu[c]:,.0f}x per CPU s")
    for x, y in (("a", "b"), ("b", "c"), ("a", "c")):
        if x in med and y in med:
            print(f"ratio {x}/{y}: {med[x] / med[y]:.2f} (per CPU s {med_cpu[x] / med_cpu[y]:.2f})")


if __name__ == "__main__":
    main()
