"""Lockstep waits stop on a grid of GuardedClock.LOCKSTEP_GRID_S simulated seconds and the
station's link checks run at every grid point (issue 14 item 6): a check (so a fault found, an
abort honoured) is never more than one grid step apart, with a quarter of the world advances and
checkpoints of 0.1 s slices."""

from __future__ import annotations

import math

import pytest

from bench.clock import SimClock
from bench.composition.sim_station import SimStation
from bench.engine.context import GuardedClock
from simulators.physics.params import preset
from simulators.world import World

GRID = GuardedClock.LOCKSTEP_GRID_S


def test_a_lockstep_wait_stops_at_every_grid_point_and_at_its_end():
    world = World(preset("hrg"), seed=0)
    clock = GuardedClock(SimClock(world))
    clock.sleep(0.15)
    seen: list[float] = []
    clock.guard = lambda: seen.append(clock.now())
    clock.sleep(3.3)  # 0.15 -> 3.45
    assert seen[0] == pytest.approx(0.15)  # the check before the wait
    assert seen[1:] == pytest.approx([GRID * k for k in range(1, 9)] + [3.45], abs=1e-9)
    assert max(b - a for a, b in zip(seen, seen[1:], strict=False)) <= GRID + 1e-9
    assert GRID <= 0.45  # a fault is found within 0.5 simulated s (a block after it fired)


def test_link_checks_run_once_per_grid_point():
    station = SimStation("sim-hrg", seed=0).open()
    try:
        table = station.devices["table"]
        times: list[float] = []
        status = table.probe_status  # the read the link check makes

        def counted():
            times.append(station.clock.now())
            return status()

        table.probe_status = counted
        station.clock.sleep(0.3)
        station.clock.guard = station.check_links
        station.clock.sleep(2.9)  # 0.3 -> 3.2: grid points 0.4 ... 3.2
        station.clock.guard = None
    finally:
        station.close()
    assert times[0] == pytest.approx(0.3)  # the first check (no check before it)
    assert times[1:] == pytest.approx([GRID * k for k in range(1, 9)], abs=1e-9)
    assert all(math.isfinite(t) for t in times)
