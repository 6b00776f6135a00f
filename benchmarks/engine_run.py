"""Engine, station and recorder figures: station open time, a recorded table-spin run's speed
in lockstep (simulated seconds per wall second, FPGA stream recorded at 1 kHz), the recorder's
raw throughput and a checkpoint's cost.  Prints its figures; median of 3."""

from __future__ import annotations

import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from bench.composition.sim_station import SimStation
from bench.engine import Runner, events
from bench.engine.context import GuardedClock
from bench.recorder import Recorder
from procedures.examples.table_spin import TableSpin


def run_speed(hold_s: float) -> tuple[float, float, float]:
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        st = SimStation("sim-hrg", seed=0).open()
        t_open = time.perf_counter() - t0
        try:
            rec = Runner(st, runs_dir=tmp).run(TableSpin, {"rate_dps": 100.0, "hold_s": hold_s})
            assert rec.outcome == "PASS", rec.end_reason
        finally:
            st.close()
        return t_open, rec.simulated_s / rec.wall_s, Path(rec.raw_file).stat().st_size / 1e6


def recorder_rows_per_s() -> float:
    with tempfile.TemporaryDirectory() as tmp:
        rec = Recorder(Path(tmp) / "b.h5")
        block = np.random.default_rng(0).normal(size=(100, 10))
        n = 2000
        t0 = time.perf_counter()
        for k in range(n):
            rec.on_event(
                events.SampleBlock(run_id="b", t_sim_s=k * 0.1, stream="fpga", columns=tuple("abcdefghij"), data=block)
            )
        dt = time.perf_counter() - t0
        rec.close()
        return n * 100 / dt


def checkpoint_us() -> float:
    class Zero:
        def now(self):
            return 0.0

        def sleep(self, dt):
            pass

    clock = GuardedClock(Zero())
    clock.guard = lambda: None
    n = 200_000
    t0 = time.perf_counter()
    for _ in range(n):
        clock.sleep(0.01)
    return (time.perf_counter() - t0) / n * 1e6


def main() -> None:
    runs = [run_speed(30.0) for _ in range(3)]
    print(f"station open (3 simulators + 3 drivers): {statistics.median(r[0] for r in runs):.2f} s")
    print(
        f"table-spin, 30 s hold, lockstep, 1 kHz FPGA stream recorded: "
        f"{statistics.median(r[1] for r in runs):.1f} simulated s per wall s "
        f"(min {min(r[1] for r in runs):.1f}, max {max(r[1] for r in runs):.1f}); raw file {runs[0][2]:.1f} MB"
    )
    rows = [recorder_rows_per_s() for _ in range(3)]
    print(f"recorder: {statistics.median(rows) / 1e6:.2f} M rows/s of 10 float64 columns (blocks of 100 rows)")
    print(f"guarded clock sleep (checkpoint) overhead: {statistics.median(checkpoint_us() for _ in range(3)):.2f} us")


if __name__ == "__main__":
    main()
