"""pytest plugin: fixtures that give a lab's own tests a simulated station and its truth.

Registered as the `gyrobench` pytest11 entry point, so any project that installs gyrobench can
use these fixtures in its own CI.
"""

from __future__ import annotations

import pytest


@pytest.fixture
def sim_world():
    """A lockstep World with the HRG preset (seed 0) and its SimClock."""
    from bench.clock import SimClock
    from simulators.physics.params import preset
    from simulators.world import World

    world = World(preset("hrg"), seed=0)
    clock = SimClock(world)
    yield world, clock
    clock.close()
