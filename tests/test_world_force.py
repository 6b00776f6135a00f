"""World.set_force keeps its own copy of each source's force (refreshed in place block after
block), and the drive's coming on is still one turn-on of the gyro."""

from __future__ import annotations

import numpy as np

from simulators.physics.noise import NOISE_PRESETS
from simulators.physics.params import preset
from simulators.world import World


def test_force_is_the_worlds_copy_and_a_turn_on_happens_once_per_drive_on():
    world = World(preset("hrg-wa"), seed=2, noise=NOISE_PRESETS["hrg-wa"])
    env = world.environment
    assert env is not None
    count0 = env.turn_on_count
    u = np.array([1.0, 2.0, 3.0, 4.0])
    world.set_force("fpga", u)
    assert env.turn_on_count == count0 + 1
    u[:] = 9.0  # the caller reuses its array: the world's force does not follow
    np.testing.assert_array_equal(world.total_force, [1.0, 2.0, 3.0, 4.0])
    world.set_force("fpga", [0.5, 0.0, 0.0, -0.5])  # refreshed while on: no new turn-on
    assert env.turn_on_count == count0 + 1
    np.testing.assert_array_equal(world.total_force, [0.5, 0.0, 0.0, -0.5])
    world.set_force("fpga", None)
    world.set_force("fpga", u)  # on again after a cut: a new turn-on
    assert env.turn_on_count == count0 + 2
    np.testing.assert_array_equal(world.total_force, [9.0, 9.0, 9.0, 9.0])
