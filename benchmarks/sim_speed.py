"""Simulated seconds per wall second: a 300 s HRG decay at 1 kHz, and a MEMS forced sweep of 61
steady states (nonlinear model, adaptive integrator).  Target for the decay: >= 1000x."""

from __future__ import annotations

import time

import numpy as np

from bench.analysis.slow_model import state_from_elements
from bench.clock import SimClock
from simulators.physics.params import MASLOV_FORCING, preset
from simulators.world import World


class Spin:
    def __init__(self, rate_dps: float) -> None:
        self.rate_dps = rate_dps
        self.n = 0

    def before_block(self, world, t_s, n, dt_s):
        world.case_rate_dps = self.rate_dps

    def after_block(self, world, block):
        self.n += len(block.index)


class Drive:
    def __init__(self, world, u) -> None:
        world.set_force("bench", u)

    def before_block(self, world, t_s, n, dt_s):
        pass

    def after_block(self, world, block):
        self.last = block.q_meas[-1]


def hrg_decay(duration_s: float = 300.0) -> float:
    world = World(preset("hrg"), seed=1, sample_period_s=1e-3)
    world.resonator.set_state(state_from_elements(1.0, 0.0, 0.0))
    spin = Spin(500.0)
    world.attach(spin)
    clock = SimClock(world)
    t0 = time.perf_counter()
    clock.sleep(duration_s)
    wall = time.perf_counter() - t0
    assert spin.n == int(duration_s * 1000)
    return duration_s / wall


def mems_sweep(points: int = 61, settle_tau: float = 6.0) -> tuple[float, float]:
    params = preset("mems")
    world = World(params, seed=1, sample_period_s=1e-3, max_block_s=0.05)
    Drive(world, np.array(MASLOV_FORCING))
    world.attach(Spin(0.0))
    clock = SimClock(world)
    settle_s = settle_tau * params.tau_s
    f0 = params.f0_hz
    t0 = time.perf_counter()
    for f in np.linspace(f0 - 15.0, f0 + 15.0, points):
        world.ref_freq_hz = float(f)
        clock.sleep(settle_s)
    wall = time.perf_counter() - t0
    return clock.now() / wall, wall


def main() -> None:
    runs = [hrg_decay() for _ in range(3)]
    print(f"HRG 300 s decay at 1 kHz (500 deg/s table): {np.median(runs):,.0f}x real time "
          f"(min {min(runs):,.0f}x, max {max(runs):,.0f}x, 3 runs)")
    speeds = [mems_sweep() for _ in range(3)]
    s = np.median([x[0] for x in speeds])
    w = np.median([x[1] for x in speeds])
    print(f"MEMS forced sweep, 61 steady states x 6 tau (cubic model, DOP853): {s:,.0f}x real time, "
          f"{w * 1000:.0f} ms wall for the sweep")


if __name__ == "__main__":
    main()
