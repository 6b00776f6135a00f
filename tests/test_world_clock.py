"""World and clock: virtual time, lockstep determinism, real-time speed factor."""

from __future__ import annotations

import time

import numpy as np
import pytest

from bench.analysis.slow_model import state_from_elements
from bench.clock import RealClock, SimClock
from simulators.physics.params import preset
from simulators.world import World


class Spin:
    def __init__(self, rate_dps: float) -> None:
        self.rate_dps = rate_dps
        self.blocks = []

    def before_block(self, world, t_s, n, dt_s):
        world.case_rate_dps = self.rate_dps

    def after_block(self, world, block):
        self.blocks.append(block)


def run(seed: int) -> np.ndarray:
    world = World(preset("hrg"), seed=seed)
    world.resonator.set_state(state_from_elements(1.0, 0.0, 0.0))
    spin = Spin(500.0)
    world.attach(spin)
    clock = SimClock(world)
    for _ in range(7):
        clock.sleep(0.37)
    return np.concatenate([b.q_meas for b in spin.blocks])


def test_same_seed_same_arrays_bit_for_bit():
    a, b = run(11), run(11)
    assert a.shape == (2590, 4)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, run(12))


def test_world_time_is_quantised_and_remainders_carry():
    world = World(preset("hrg"), seed=0, sample_period_s=1e-3)
    spin = Spin(0.0)
    world.attach(spin)
    for _ in range(10):
        world.advance(0.00025)  # four quarter-samples make one sample
    assert world.sample_index == 2
    world.advance(1.0)
    assert world.t_s == pytest.approx(1.0025 - 0.0005, abs=1e-12)
    idx = np.concatenate([b.index for b in spin.blocks])
    assert np.array_equal(idx, np.arange(1, len(idx) + 1))
    assert max(len(b.index) for b in spin.blocks) <= world.max_block_samples


def test_devices_limit_block_size():
    class Fine(Spin):
        def max_block_samples(self, world):
            return 3

    world = World(preset("hrg"), seed=0)
    dev = Fine(1.0)
    world.attach(dev)
    world.advance(0.05)
    assert [len(b.index) for b in dev.blocks][:3] == [3, 3, 3]


@pytest.mark.serial  # 300 simulated s within 5 s of wall time: run alone
def test_lockstep_sleep_and_wait_until_use_virtual_time():
    world = World(preset("hrg"), seed=0)
    clock = SimClock(world)
    t0 = time.monotonic()
    clock.sleep(300.0)
    assert clock.now() == pytest.approx(300.0)
    assert time.monotonic() - t0 < 5.0  # far faster than real time
    assert clock.wait_until(lambda: clock.now() >= 310.0, timeout_s=20.0, poll_s=0.5)
    assert clock.now() == pytest.approx(310.0, abs=1e-9)
    assert not clock.wait_until(lambda: False, timeout_s=2.0, poll_s=0.5)
    assert clock.now() == pytest.approx(312.0, abs=1e-9)


@pytest.mark.serial  # real-time pacing at 50x, a wall-clock window: run alone
def test_real_time_mode_follows_wall_clock_times_speed():
    world = World(preset("hrg"), seed=0)
    clock = SimClock(world, speed=50.0)
    try:
        t0 = time.monotonic()
        clock.sleep(5.0)  # 0.1 s of wall time at 50x
        wall = time.monotonic() - t0
        assert clock.now() >= 5.0 - 1e-9
        assert 0.05 < wall < 3.0
        clock.set_speed(float("inf"))  # switch to lockstep mid-run
        t1 = clock.now()
        clock.sleep(100.0)
        assert clock.now() >= t1 + 100.0 - 1e-9
    finally:
        clock.close()


def test_clock_rejects_bad_waits():
    world = World(preset("hrg"), seed=0)
    clock = SimClock(world)
    with pytest.raises(ValueError, match="dt_s=-1"):
        clock.sleep(-1)
    with pytest.raises(ValueError, match="speed=0"):
        clock.set_speed(0)
    with pytest.raises(ValueError, match="nan"):
        RealClock().sleep(float("nan"))


@pytest.mark.serial  # real-time pacing at 20x, a wall-clock bound: run alone
def test_a_dead_real_time_thread_raises_in_the_waiter_then_runs_lockstep():
    """A device that fails inside the world's advance in real-time mode: the wait raises (it does
    not hang), and the clock goes on in lockstep so a safe state can still wait."""

    class Breaks:
        def __init__(self) -> None:
            self.armed = True

        def before_block(self, world, t_s, n, dt_s):
            if self.armed and t_s > 0.5:
                self.armed = False
                raise ValueError("device bug")

        def after_block(self, world, block):
            pass

    world = World(preset("hrg"), seed=0)
    world.attach(Breaks())
    clock = SimClock(world, speed=20.0)
    try:
        t0 = time.monotonic()
        with pytest.raises(RuntimeError, match="device bug"):
            clock.sleep(5.0)
        assert time.monotonic() - t0 < 5.0
        assert clock.lockstep
        t1 = clock.now()
        clock.sleep(1.0)
        assert clock.now() == pytest.approx(t1 + 1.0, abs=1e-9)
    finally:
        clock.close()
