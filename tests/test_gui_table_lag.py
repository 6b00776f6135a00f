"""The window's table-rate curve keeps up with its FPGA curves at "max": the table's rows come
from the link checks (one a lockstep grid step), recorded in blocks; 32 rows were 12.8 s of bench
time, and the table curve trailed the FPGA's (blocks a grid step long) by up to that.  A block
now spans at most Station.HEALTH_BLOCK_SIM_S of bench time, whatever the wall clock does."""

from __future__ import annotations

import numpy as np
import pytest

from bench.composition.sim_station import SimStation
from bench.engine.context import GuardedClock
from bench.station import Station


class _Recorded:
    """A run context's `record` only: each table block with the bench time it was recorded at."""

    def __init__(self, clock) -> None:
        self.clock = clock
        self.blocks: list[tuple[float, np.ndarray]] = []

    def record(self, stream, columns, data) -> None:
        if stream == "table":
            self.blocks.append((self.clock.now(), np.asarray(data)))


def test_table_rows_reach_the_run_within_a_bounded_bench_time(monkeypatch):
    import gc

    gc.collect()  # earlier tests' Qt garbage freed here, in the GUI thread, not by the station's threads
    monkeypatch.setattr(Station, "HEALTH_BLOCK_WALL_S", float("inf"))  # as at "max": the wall never flushes
    station = SimStation("sim-hrg", seed=0).open()
    try:
        ctx = _Recorded(station.clock)
        station._ctx = ctx  # what start_streams sets for a run
        station.clock.guard = station.check_links
        station.clock.sleep(30.0)
        station.clock.guard = None
    finally:
        station._ctx = None
        station.close()
    assert len(ctx.blocks) >= 10
    grid = GuardedClock.LOCKSTEP_GRID_S
    rows = np.concatenate([b for _, b in ctx.blocks])
    np.testing.assert_allclose(np.diff(rows[:, 0]), grid, atol=1e-9)  # every grid point's row, in order
    for t_recorded, block in ctx.blocks:  # the oldest row of a block waited at most the bound (+ a grid step)
        assert t_recorded - block[0, 0] <= Station.HEALTH_BLOCK_SIM_S + grid + 1e-9
    assert Station.HEALTH_BLOCK_SIM_S <= 2.0 + 1e-12 < 32 * grid
    assert ctx.blocks[-1][0] == pytest.approx(30.0, abs=Station.HEALTH_BLOCK_SIM_S + grid)
