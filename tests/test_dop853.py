"""The compiled DOP853 of the nonlinear resonator (simulators/physics/dop853.py) is scipy's method
step for step: the same accepted steps, the same samples to rounding, on the MEMS ring's model."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.integrate._ivp.rk import DOP853

from bench.analysis.slow_model import k_cubic, k_quintic, linear_matrix
from simulators.physics.averaged import Resonator
from simulators.physics.dop853 import TOO_SMALL_STEP, integrate_block, nonlinear_block, tableau
from simulators.physics.params import preset


def _cases(seed: int, count: int):
    """Random blocks of the MEMS ring's model: rates, detunings, forcing, amplitudes, block lengths."""
    rng = np.random.default_rng(seed)
    c = preset("mems").coefficients()
    for i in range(count):
        a = linear_matrix(c.zg(rng.normal(0.0, 0.5)), rng.normal(0.0, 20.0))
        xi = c.xi * (1.0 + rng.normal())
        kappa = 0.0 if i % 2 else 0.3 * rng.random()
        u, q0 = rng.normal(0.0, 5.0, 4), rng.normal(0.0, 1.0, 4)
        n, dt = int(rng.integers(1, 100)), float(rng.choice([5e-4, 1e-3, 2e-3, 1e-2]))
        yield a, u, xi, kappa, q0, dt, n


def _rhs(a, u, xi, kappa):
    return lambda _t, q: a @ q + 0.5 * u + 0.5 * xi * k_cubic(q) + 0.5 * kappa * k_quintic(q)


def test_the_samples_equal_scipys_dop853_to_rounding():
    worst = 0.0
    for a, u, xi, kappa, q0, dt, n in _cases(seed=1, count=200):
        ref = solve_ivp(_rhs(a, u, xi, kappa), (0.0, n * dt), q0, t_eval=dt * np.arange(1, n + 1), method="DOP853",
                        rtol=1e-9, atol=1e-12, first_step=dt)
        mine = integrate_block(a, u, xi, kappa, q0, dt, n)
        worst = max(worst, float(np.max(np.abs(mine - ref.y.T)) / np.max(np.abs(ref.y))))
    assert worst < 1e-12  # 4e-13 measured: only the arithmetic's order differs


def test_the_accepted_steps_are_scipys():
    tab = tableau()
    counted = 0
    for a, u, xi, kappa, q0, dt, n in _cases(seed=2, count=60):
        solver = DOP853(_rhs(a, u, xi, kappa), 0.0, q0, n * dt, rtol=1e-9, atol=1e-12, first_step=dt)
        steps = 0
        while solver.status == "running":
            solver.step()
            steps += 1
        out = np.empty((n, 4))
        mine = nonlinear_block(a, 0.5 * u, 0.5 * xi, 0.5 * kappa, q0, dt, n, 1e-9, 1e-12, *tab, out)
        assert mine == steps
        counted += steps
    assert counted > 60  # blocks of more than one step were among them


def test_a_step_under_the_minimum_is_reported_not_looped():
    """A state whose right-hand side overflows (a NaN error norm) shrinks the step under scipy's
    minimum: the kernel says so at once, as scipy fails, instead of stepping on a NaN."""
    a, u, q0 = -np.eye(4), np.zeros(4), np.full(4, 1e200)
    out = np.empty((5, 4))
    assert nonlinear_block(a, u, 0.5, 0.0, q0, 1.0, 5, 1e-9, 1e-12, *tableau(), out) == TOO_SMALL_STEP
    with pytest.raises(RuntimeError, match="under its minimum"):
        integrate_block(a, u, 1.0, 0.0, q0, 1.0, 5)
    with np.errstate(all="ignore"):
        assert solve_ivp(_rhs(a, u, 1.0, 0.0), (0.0, 5.0), q0, method="DOP853", first_step=1.0).status == -1


def test_the_ring_resonator_follows_scipy_over_a_free_decay():
    """The MEMS ring's Resonator, block by block, against one scipy integration of the whole decay."""
    params = preset("mems")
    res = Resonator(params, seed=0, state=np.array([1.0, 0.0, 0.2, 0.1]))
    c = params.coefficients()
    a = linear_matrix(c.zg(0.0), 0.0)
    q0 = res.state
    blocks = [res.step_block(50, 1e-3) for _ in range(20)]
    ref = solve_ivp(_rhs(a, np.zeros(4), c.xi, c.kappa), (0.0, 1.0), q0, method="DOP853", rtol=1e-11, atol=1e-14,
                    t_eval=1e-3 * np.arange(1, 1001))
    assert np.max(np.abs(np.concatenate(blocks) - ref.y.T)) < 1e-8  # the tolerance's scale, block restarts and all
