"""The resonator's exact linear step (force carried as state, compiled kernel) against a direct
scipy expm of the forced system, step by step: both are exact, so they agree to rounding."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.linalg import expm

from bench.analysis.slow_model import linear_matrix
from simulators.physics.averaged import Resonator
from simulators.physics.params import ResonatorParams


def _reference(q0: np.ndarray, a: np.ndarray, u: np.ndarray, n: int, dt: float) -> np.ndarray:
    """x_{k+1} = expm([[A, u/2], [0, 0]] dt) x_k on (q, 1): the forced step straight from scipy."""
    aug = np.zeros((5, 5))
    aug[:4, :4] = a
    aug[:4, 4] = 0.5 * u
    phi = expm(aug * dt)
    x = np.append(q0, 1.0)
    out = np.empty((n, 4))
    for k in range(n):
        x = phi @ x
        out[k] = x[:4]
    return out


PARAMS = ResonatorParams(
    f0_hz=5500.0, tau_s=3.0, delta_inv_tau_per_s=0.05, theta_tau_deg=20.0, split_hz=0.3, theta_w_deg=10.0
)


@pytest.mark.parametrize("rate_dps, ref_offset_hz", [(0.0, 0.0), (500.0, 0.0), (-30.0, 0.7)])
def test_forced_blocks_with_a_new_force_each_block_match_scipy_expm(rate_dps, ref_offset_hz):
    rng = np.random.default_rng(1)
    r = Resonator(PARAMS, state=np.array([0.9, -0.2, 0.3, 0.1]))
    c = r.coeffs
    rate = math.radians(rate_dps)
    ref = PARAMS.f0_hz + ref_offset_hz
    a = linear_matrix(c.zg(rate), r.detuning_rad_s(ref))
    q = r.state
    dt = 1e-3
    for n in (1, 7, 50, 50, 100, 3):  # block sizes as the world makes them; force changes every block
        u = rng.normal(0.0, 0.5, 4)
        got = r.step_block(n, dt, rate_rad_s=rate, force=u, ref_freq_hz=ref)
        want = _reference(q, a, u, n, dt)
        # both exact: the difference is rounding of ~100 products of O(1) matrices
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
        q = want[-1]


def test_long_block_matches_scipy_expm():
    r = Resonator(PARAMS, state=np.array([1.0, 0.0, 0.0, 0.0]))
    u = np.array([0.1, -0.05, 0.02, 0.3])
    got = r.step_block(1000, 1e-3, force=u, ref_freq_hz=PARAMS.f0_hz)
    want = _reference(np.array([1.0, 0.0, 0.0, 0.0]), linear_matrix(r.coeffs.zg(0.0), 0.0), u, 1000, 1e-3)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
    assert r.step_block(1, 1e-3, force=u, ref_freq_hz=PARAMS.f0_hz).shape == (1, 4)


def test_unforced_step_is_the_plain_matrix_exponential():
    r = Resonator(PARAMS, state=np.array([0.3, 0.4, -0.5, 0.1]))
    a = linear_matrix(r.coeffs.zg(math.radians(100.0)), 0.0)
    got = r.step_block(20, 1e-2, rate_rad_s=math.radians(100.0))
    phi = expm(a * 1e-2)
    want = [np.linalg.matrix_power(phi, k) @ np.array([0.3, 0.4, -0.5, 0.1]) for k in range(1, 21)]
    np.testing.assert_allclose(got, np.array(want), rtol=0, atol=1e-13)


def test_compiled_linear_matrix_is_the_model_s():
    from simulators.physics.kernels import linear_matrix_into

    zg = np.random.default_rng(3).normal(size=8)
    got = np.empty((4, 4))
    linear_matrix_into(zg, 1.7, got)
    np.testing.assert_allclose(got, linear_matrix(zg, 1.7), rtol=0, atol=1e-15)
