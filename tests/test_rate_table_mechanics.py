"""TableMechanics as a World device, without a server: profile, lag, world coupling, seeds."""

from __future__ import annotations

import math

import numpy as np
import pytest

from drivers.rate_table import modbus_protocol as mp
from simulators.physics.params import preset
from simulators.rate_table import CommandRejected, TableMechanics
from simulators.world import World


def make(seed: int = 0, **kw):
    world = World(preset("hrg"), seed=seed)
    kw.setdefault("watchdog_s", 0.0)  # no wall-clock watchdog unless a test asks for one
    mech = TableMechanics(seed=seed, **kw)
    world.attach(mech)
    mech.set_enabled(True)
    return world, mech


def test_ramp_follows_accel_limit_through_the_lag():
    """Truth: a ramp a*t through a first-order lag tau gives a*(t - tau(1 - exp(-t/tau))); the
    discrete loop holds ref per 1 ms sample, so tolerance a*dt = 0.1 deg/s."""
    world, mech = make()
    a, tau = 100.0, mech.tau_s
    mech.command(mp.MODE_RATE, 500.0, 0.0, a)
    world.advance(2.0)
    expected = a * (2.0 - tau * (1 - math.exp(-2.0 / tau)))
    assert mech.rate_dps == pytest.approx(expected, abs=a * world.sample_period_s)


def test_world_sees_the_table_rate_and_angle():
    world, mech = make()
    mech.command(mp.MODE_RATE, 200.0, 0.0, 400.0)
    world.advance(3.0)
    assert world.case_rate_dps == pytest.approx(200.0, abs=1e-9)
    assert world.case_angle_deg == pytest.approx(mech.angle_deg, abs=1e-6)
    ripple = np.degrees(world.ripple_angle_rad)
    bound = sum(mech.ripple_deg) + 6 * mech.noise_deg  # periodic ripple + 6 sigma of jitter
    assert 0 < np.max(np.abs(ripple)) <= bound
    assert np.mean(world.last_block.rate_dps) == pytest.approx(200.0, abs=0.05)


def test_small_blocks_only_while_moving():
    world, mech = make()
    assert mech.max_block_samples(world) is None
    mech.command(mp.MODE_RATE, 50.0, 0.0, 100.0)
    assert mech.max_block_samples(world) == mech.accel_block_samples
    world.advance(2.0)
    assert mech.max_block_samples(world) is None


def test_seeded_and_reproducible():
    def run(seed):
        world, mech = make(seed)
        mech.command(mp.MODE_RATE, 100.0, 0.0, 200.0)
        world.advance(1.0)
        return mech.status(), world.state()

    (s1, q1), (s2, q2), (s3, _) = run(5), run(5), run(6)
    assert s1 == s2 and np.array_equal(q1, q2)
    assert s1[0] != s3[0]


def test_bad_commands_are_rejected():
    world, mech = make(max_rate_dps=600.0, max_accel_dps2=500.0)
    for args in [
        (5, 0.0, 0.0, 10.0),
        (1, 700.0, 0.0, 10.0),
        (1, 10.0, 0.0, 0.0),
        (2, 10.0, 360.0, 10.0),
        (1, math.nan, 0.0, 10.0),
    ]:
        with pytest.raises(CommandRejected) as err:
            mech.command(*args)
        assert err.value.bad_value
    mech.set_enabled(False)
    with pytest.raises(CommandRejected) as err:
        mech.command(mp.MODE_RATE, 10.0, 0.0, 10.0)
    assert not err.value.bad_value
    with pytest.raises(ValueError):
        mech.inject("meteor")


def test_watchdog_on_an_injected_wall_clock():
    wall = [0.0]
    world, mech = make(watchdog_s=1.0, wall_clock=lambda: wall[0])
    mech.command(mp.MODE_RATE, 100.0, 0.0, 200.0)
    world.advance(1.0)
    wall[0] = 0.9
    mech.feed()
    wall[0] = 1.8
    world.advance(0.1)
    assert not mech.watchdog_expired
    wall[0] = 3.0
    world.advance(0.1)
    assert not mech.watchdog_expired  # 2.1 s of wall silence, but only 0.2 s of simulated time
    world.advance(1.0)
    assert mech.watchdog_expired and mech.fault_code == mp.FAULT_WATCHDOG
    world.advance(1.0)  # ramps down at 200 deg/s^2, then disables
    assert not mech.enabled and mech.rate_dps == 0.0


def test_starved_heartbeat_does_not_trip_a_table_read_in_lockstep():
    """A loaded machine: no write for 10 s of wall time while lockstep reads the table at every
    0.4 s grid point: the host is alive in simulated time, no trip.  When the reads stop too, the
    watchdog expires within one block of watchdog_s of simulated silence."""
    wall = [0.0]
    world, mech = make(watchdog_s=1.0, wall_clock=lambda: wall[0])
    mech.command(mp.MODE_RATE, 20.0, 0.0, 200.0)
    wall[0] = 10.0
    for _ in range(10):
        world.advance(0.4)
        mech.status()
    assert not mech.watchdog_expired and mech.enabled
    t_read = world.t_s
    world.advance(0.9)
    assert not mech.watchdog_expired
    world.advance(0.3)  # blocks of at most 0.1 s: one starts more than 1 s after the read
    assert mech.watchdog_expired and mech.fault_code == mp.FAULT_WATCHDOG
    assert world.t_s - t_read > 1.0
