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


@pytest.fixture
def sim_station(request):
    """An opened simulated station (built-in `sim-hrg`, seed 0, lockstep), closed afterwards.
    Choose another with `@pytest.mark.parametrize("sim_station", ["sim-mems"], indirect=True)`."""
    from bench.composition.sim_station import SimStation

    name = getattr(request, "param", "sim-hrg")
    station = SimStation(name, seed=0).open()
    try:
        yield station
    finally:
        station.close()


@pytest.fixture
def sim_truth(sim_station):
    """The true parameters of the simulated station, under the measurements' names."""
    return sim_station.truth()


@pytest.fixture
def run_procedure(sim_station, tmp_path):
    """run_procedure(ProcedureClass, {params}) -> RunRecord on the simulated station, with the
    raw file and results store in a temporary directory."""
    from bench.engine import Runner
    from bench.results import ResultsStore

    store = ResultsStore(tmp_path / "results.sqlite")

    def run(procedure, params=None, *, faults=()):
        for kind, at_s in faults:
            sim_station.schedule_fault(kind, at_s)
        return Runner(sim_station, runs_dir=tmp_path / "runs", store=store).run(procedure, params)

    yield run
    store.close()
