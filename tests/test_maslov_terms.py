"""The averaged terms of Maslov et al. against first-principles averaging, the printed formulas and
a carrier-level integration."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from bench.analysis.maslov import k_electrostatic, k_quintic_printed
from bench.analysis.maslov_terms import forcing_block, nonlinear_columns
from bench.analysis.slow_model import k_cubic, k_quintic, linear_matrix, orbit_elements, slow_rhs, state_from_elements
from simulators.physics.carrier import integrate_carrier, iq_demodulate
from simulators.physics.params import ResonatorParams

RNG_STATES = np.random.default_rng(7).normal(size=(25, 4))


def averaged_force(q: np.ndarray, force_fn, n_quad: int = 64) -> np.ndarray:
    """First-order averaging of a perturbation (F_f, F_g) = force_fn(f, g, wt) of
    f'' + w^2 f = w F_f: 2 dq1/dt = -2 <F_f sin>, 2 dp1/dt = 2 <F_f cos> (same for g).
    The integrands are trigonometric polynomials of degree <= 6, so an n-point rectangle rule
    with n > 6 is exact."""
    phase = 2 * math.pi * np.arange(n_quad) / n_quad
    s, c = np.sin(phase), np.cos(phase)
    q1, p1, q2, p2 = q
    f = p1 * s + q1 * c
    g = p2 * s + q2 * c
    ff, fg = force_fn(f, g, phase)
    return np.array([-2 * np.mean(ff * s), 2 * np.mean(ff * c), -2 * np.mean(fg * s), 2 * np.mean(fg * c)])


@pytest.mark.parametrize("q", RNG_STATES[:8])
def test_cubic_and_quintic_terms_are_the_average_of_the_power_law_forces(q):
    """Truth: quadrature of (f^2+g^2)^m (f, g); agreement to rounding (1e-12)."""
    cubic = averaged_force(q, lambda f, g, _ph: ((f * f + g * g) * f, (f * f + g * g) * g))
    quintic = averaged_force(q, lambda f, g, _ph: ((f * f + g * g) ** 2 * f, (f * f + g * g) ** 2 * g))
    np.testing.assert_allclose(k_cubic(q), cubic, atol=1e-12)
    np.testing.assert_allclose(k_quintic(q), quintic, atol=1e-12)


def test_printed_quintic_terms_are_half_the_derived_ones_and_k6_has_a_misplaced_parenthesis():
    derived = k_quintic(RNG_STATES)
    fixed = k_quintic_printed(RNG_STATES, fix_k6_parenthesis=True)
    np.testing.assert_allclose(2.0 * fixed, derived, rtol=1e-12, atol=1e-12)
    as_printed = k_quintic_printed(RNG_STATES)
    np.testing.assert_allclose(2.0 * as_printed[:, [0, 2, 3]], derived[:, [0, 2, 3]], rtol=1e-12, atol=1e-12)
    assert np.max(np.abs(2.0 * as_printed[:, 1] - derived[:, 1])) > 1.0  # the printed k6 is not the average


@pytest.mark.parametrize("q", RNG_STATES[:6])
def test_electrostatic_terms_k9_to_k14_are_the_average_of_the_actuator_nonlinearity(q):
    """eta (1 + 3 mu f^2)(-u1 sin + u2 cos) averaged; the paper's printed k9..k14 (eq. 3.2) hold."""
    mu = 0.37
    u = np.array([0.3, -0.7, 1.1, 0.4])

    def force(f, g, ph):
        return (
            (1 + 3 * mu * f * f) * (-u[0] * np.sin(ph) + u[1] * np.cos(ph)),
            (1 + 3 * mu * g * g) * (-u[2] * np.sin(ph) + u[3] * np.cos(ph)),
        )

    np.testing.assert_allclose(forcing_block(q, mu) @ u, averaged_force(q, force), atol=1e-12)
    k9, k10, k11, k12, k13, k14 = k_electrostatic(q)
    q1, p1, q2, p2 = q
    assert k9 == pytest.approx(-1.5 * q1 * p1) and k10 == pytest.approx(-1.5 * q2 * p2)
    assert k11 == pytest.approx(0.75 * (3 * p1**2 + q1**2)) and k14 == pytest.approx(0.75 * (p2**2 + 3 * q2**2))
    assert k12 == pytest.approx(0.75 * (p1**2 + 3 * q1**2)) and k13 == pytest.approx(0.75 * (3 * p2**2 + q2**2))


def test_quintic_terms_against_a_carrier_level_integration():
    """A quintic-dominated wave with quadrature (so X != 0 matters): the demodulated carrier-level
    integration follows the averaged model with the derived k5..k8; the printed ones (half the
    size, k6 broken) miss it by far more.  Averaging error is O(kappa a^4 / w) ~ 1e-2 here at
    w = 2 pi 50, hence the 1e-2 tolerance; the printed terms miss by ~0.2."""
    p = ResonatorParams(f0_hz=50.0, tau_s=4.0, kappa_per_s=1.6, split_hz=0.02, theta_w_deg=20.0)
    q0 = state_from_elements(1.0, 0.35, 0.3, 0.0)
    fs, duration = 4000.0, 1.2
    t, x, y = integrate_carrier(p, q0, duration, fs_hz=fs)
    tc, cx, sx = iq_demodulate(t, x, 50.0, fs)
    _, cy, sy = iq_demodulate(t, y, 50.0, fs)
    c = p.coefficients()
    a = linear_matrix(c.zg(0.0))

    def averaged(quintic):
        def rhs(_t, q):
            return a @ q + 0.5 * c.kappa * quintic(q)

        return solve_ivp(rhs, (0.0, duration), q0, dense_output=True, rtol=1e-10, atol=1e-12).sol

    good = averaged(k_quintic)
    bad = averaged(lambda q: k_quintic_printed(q))
    t_check = np.array([0.4, 0.8, 1.1])
    demod = np.stack([np.interp(t_check, tc, s) for s in (cx, sx, cy, sy)], axis=-1)
    err_good = np.max(np.abs(good(t_check).T - demod))
    err_bad = np.max(np.abs(bad(t_check).T - demod))
    assert err_good < 1e-2
    assert err_bad > 10 * err_good


def test_nonlinear_columns_shapes_and_orbit_drift_uses_the_damping_axis_beta():
    """Eq. 5.9 with the b_m terms at the damping axis beta (the paper writes alpha): the wave's
    drift from the slow model equals (r^2+k^2)/(4(r^2-k^2)) b_m sin 4(theta - beta) - ... at k = 0."""
    q = state_from_elements(1.0, 0.0, math.radians(17.0), 0.4)
    assert nonlinear_columns(q, "linear").shape == (4, 0)
    assert nonlinear_columns(q, "quintic").shape == (4, 2)
    b_m, beta = 0.3, math.radians(-11.5)
    zg = np.array([0.1, 0.0, b_m * math.cos(4 * beta), b_m * math.sin(4 * beta), 0.0, 0.0, 0.0, 0.0])
    h = 1e-6
    th = [orbit_elements(q + s * h * slow_rhs(q, zg))["theta_rad"] for s in (-1, 1)]
    dtheta = (th[1] - th[0]) / (2 * h)
    assert dtheta == pytest.approx(0.25 * b_m * math.sin(4 * (math.radians(17.0) - beta)), rel=1e-6)


@pytest.mark.parametrize("model", ["cubic", "quintic"])
def test_analytic_jacobian_of_the_nonlinear_columns(model):
    """Truth: central differences (step 1e-5, error ~1e-9 for these polynomials)."""
    from bench.analysis.maslov_terms import nonlinear_jacobian, numeric_jacobian

    jac = nonlinear_jacobian(RNG_STATES, model)
    for col in range(jac.shape[-1]):
        num = numeric_jacobian(lambda x, col=col: nonlinear_columns(x, model)[..., col], RNG_STATES, 1e-5)
        np.testing.assert_allclose(jac[..., col], num, atol=1e-7)
    weights = np.array([0.7, -1.3])[: jac.shape[-1]]
    np.testing.assert_allclose(nonlinear_jacobian(RNG_STATES, model, weights), jac @ weights, atol=1e-12)
