"""Output-error (maximum-likelihood) free-decay fit and its Cramer-Rao bound, against the
simulator's `Resonator` truth: exact sensitivities, recovery within intervals, scatter at the
bound on a seeded Monte Carlo, and named errors on bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bench.analysis.damping_design import DecayScenario, crlb_free_decay, four_channel_bound
from bench.analysis.free_decay_oe import (
    FreeDecayFitError,
    linear_sensitivities,
    nonlinear_sensitivities,
    output_error_fit,
    trajectory,
)
from bench.analysis.free_decay_rk import substeps_for
from bench.analysis.maslov import identify_free_decay
from bench.analysis.slow_model import LINEAR_PARAM_NAMES, linear_matrix, state_from_elements
from simulators.physics.averaged import Resonator
from simulators.physics.params import preset

RATE_RAD_S = math.radians(20.0)
Q0 = state_from_elements(1.0, 0.02, math.radians(17.0))


def decay(params, *, seed: int, fs_hz: float, duration_s: float):
    res = Resonator(params, seed=seed, state=Q0)
    n = int(round(duration_s * fs_hz))
    traj = np.vstack([Q0, res.step_block(n, 1.0 / fs_hz, rate_rad_s=RATE_RAD_S)])
    return np.arange(n + 1) / fs_hz, res.measure(traj)


def truth(params) -> dict[str, float]:
    c = params.coefficients()
    out = dict(zip(LINEAR_PARAM_NAMES, c.zg(RATE_RAD_S), strict=True))
    out.update(xi=c.xi, kappa=c.kappa)
    return out


def z_of(params, model: str) -> np.ndarray:
    tr = truth(params)
    names = LINEAR_PARAM_NAMES + {"linear": (), "cubic": ("xi",), "quintic": ("xi", "kappa")}[model]
    return np.array([tr[n] for n in names])


@pytest.mark.parametrize("model", ["linear", "cubic", "quintic"])
def test_sensitivities_match_finite_differences(model):
    """The exact (linear: expm of the augmented system) and integrated (sensitivity equations)
    Jacobians equal central differences of the trajectory to 1e-5 relative."""
    p = preset("hrg", xi_per_s=0.05 if model != "linear" else 0.0, kappa_per_s=0.02 if model == "quintic" else 0.0)
    z = z_of(p, model)
    t = np.arange(301) / 2.0
    q, jac = trajectory(t, Q0, z, model)
    theta = np.concatenate([Q0, z])
    for j in range(theta.size):
        h = 1e-6 * max(abs(theta[j]), 1e-3)
        up, dn = theta.copy(), theta.copy()
        up[j] += h
        dn[j] -= h
        fd = (trajectory(t, up[:4], up[4:], model, jac=False)[0] - trajectory(t, dn[:4], dn[4:], model, jac=False)[0])
        fd /= 2 * h
        assert np.max(np.abs(jac[:, :, j] - fd)) < 1e-5 * np.max(np.abs(fd)) + 1e-9, j


@pytest.mark.parametrize("model", ["cubic", "quintic"])
def test_compiled_rk4_equals_dop853(model):
    """On a uniform grid the nonlinear model is integrated by compiled fixed-step RK4 (with
    substeps at a coarse grid); it equals the DOP853 path (rtol 1e-9, taken for a non-uniform
    grid) to 1e-8 in the trajectory and 1e-7 (relative) in the sensitivities."""
    p = preset("hrg", xi_per_s=0.05, kappa_per_s=0.02 if model == "quintic" else 0.0)
    z = z_of(p, model)
    big = math.radians(300.0)  # a fast table: nu = 4 K Omega needs substeps at 2 Hz
    z[1] = 4.0 * p.bryan_factor * big
    t = np.arange(401) / 2.0
    assert substeps_for(linear_matrix(z[:8]), z[8], z[9] if model == "quintic" else 0.0, Q0, 0.5) > 1
    q_rk, s_rk = nonlinear_sensitivities(z, Q0, t, model)
    t_odd = t.copy()
    t_odd[-1] += 1e-6  # not uniform: the DOP853 path
    q_dp, s_dp = nonlinear_sensitivities(z, Q0, t_odd, model)
    assert np.max(np.abs(q_rk[:-1] - q_dp[:-1])) < 1e-8
    assert np.max(np.abs(s_rk[:-1] - s_dp[:-1])) < 1e-7 * np.max(np.abs(s_dp))


def test_nonlinear_path_equals_linear_at_zero_xi():
    """The cubic model with xi = 0 integrates to the linear closed form (trajectory and Jacobian)."""
    p = preset("hrg")
    z = z_of(p, "cubic")
    t = np.arange(3001) / 10.0
    ql, jl = trajectory(t, Q0, z[:8], "linear")
    qc, jc = trajectory(t, Q0, z, "cubic")
    assert np.max(np.abs(ql - qc)) < 1e-8  # RK4 at 0.01 rad per substep
    assert np.max(np.abs(jl - jc[:, :, :12])) < 1e-8 * np.max(np.abs(jl))


@pytest.mark.parametrize("model", ["linear", "cubic"])
def test_output_error_recovers_truth_within_intervals(model):
    """Each estimate within 3.3 standard errors of the simulator's truth (99.9 % per parameter),
    the noise estimate within 2 % of the simulator's, the std errors at the CRLB (within 2 %)
    and the equation-error start much wider for gamma and nu."""
    p = preset("hrg", xi_per_s=0.05 if model == "cubic" else 0.0)
    t, q = decay(p, seed=5, fs_hz=20.0, duration_s=300.0)
    oe = identify_free_decay(t, *q.T, model=model, method="output-error", natural_freq_hz=p.f0_hz)
    ee = identify_free_decay(t, *q.T, model=model)
    tr = truth(p)
    bound = crlb_free_decay(duration_s=300.0, stream_hz=20.0, noise_sigma=p.noise_sigma, q0=Q0,
                            params=tr, model=model)
    assert oe.method == "free_decay_output_error"
    for name in oe.params:
        assert abs(oe.params[name] - tr[name]) < 3.3 * oe.sigma_params[name], name
        lo, hi = oe.ci95[name]
        assert lo < oe.params[name] < hi
        assert oe.sigma_params[name] == pytest.approx(bound.std[name] * oe.noise_sigma / p.noise_sigma, rel=0.02)
    assert oe.noise_sigma == pytest.approx(p.noise_sigma, rel=0.02)
    assert ee.sigma_params["gamma"] > 10 * oe.sigma_params["gamma"]
    assert oe.derived["Q"] == pytest.approx(p.q_factor, rel=1e-3)
    assert set(oe.extras["start"]) == set(oe.params)


def test_output_error_scatter_at_the_cramer_rao_bound():
    """40 seeded decays (10 Hz, 300 s, linear): the scatter of every parameter within 0.75..1.3
    of its CRLB (the std of a 40-seed std is 11 %), and the 95 % intervals cover >= 34 of 40."""
    p = preset("hrg", split_hz=0.01)
    tr = truth(p)
    bound = crlb_free_decay(duration_s=300.0, stream_hz=10.0, noise_sigma=p.noise_sigma, q0=Q0, params=tr)
    est, cover = [], np.zeros(8)
    for seed in range(40):
        t, q = decay(p, seed=100 + seed, fs_hz=10.0, duration_s=300.0)
        oe = identify_free_decay(t, *q.T, method="output-error")
        est.append([oe.params[n] - tr[n] for n in LINEAR_PARAM_NAMES])
        cover += [oe.ci95[n][0] <= tr[n] <= oe.ci95[n][1] for n in LINEAR_PARAM_NAMES]
    ratio = np.sqrt(np.mean(np.square(est), axis=0)) / np.array([bound.std[n] for n in LINEAR_PARAM_NAMES])
    assert np.all((ratio > 0.75) & (ratio < 1.3)), dict(zip(LINEAR_PARAM_NAMES, ratio.round(3), strict=True))
    assert np.all(cover >= 34), cover


def test_crlb_agrees_with_four_channel_bound():
    """crlb_free_decay and four_channel_bound share one information path: at a stream slow enough
    for the design grid to take every sample they agree."""
    sc = DecayScenario(tau_s=300.0, delta_inv_tau_per_s=1.6e-4, noise_sigma=1e-4, rate_dps=20.0, duration_s=300.0,
                       stream_hz=1.0, split_hz=0.005, quadrature=0.02, theta_tau_deg=20.0)
    assert sc.grid_step()[1] == 1
    fc = four_channel_bound(sc)
    params = dict(zip(LINEAR_PARAM_NAMES, sc.zg(), strict=True))
    cb = crlb_free_decay(duration_s=300.0, stream_hz=1.0, noise_sigma=1e-4, q0=sc.initial_state(), params=params)
    assert cb.std_delta_inv_tau_per_s == pytest.approx(fc.std_delta_inv_tau_per_s, rel=1e-9)
    assert cb.std_theta_tau_deg == pytest.approx(fc.std_theta_tau_deg, rel=1e-9)
    np.testing.assert_allclose(np.sqrt(np.diag(cb.covariance)), np.sqrt(np.diag(fc.covariance)), rtol=1e-9)


def test_recursive_start_and_sandwich():
    """The start (batch or recursive EE) does not move the optimum (to 1e-3 standard error); the
    Newey-West sandwich under white noise is within 20 % of the Fisher interval."""
    p = preset("hrg")
    t, q = decay(p, seed=9, fs_hz=10.0, duration_s=300.0)
    a = identify_free_decay(t, *q.T, method="output-error")
    b = identify_free_decay(t, *q.T, method="output-error", recursive=True)
    s = identify_free_decay(t, *q.T, method="output-error", covariance="sandwich")
    for name in a.params:
        assert abs(a.params[name] - b.params[name]) < 1e-3 * a.sigma_params[name], name
        assert s.sigma_params[name] == pytest.approx(a.sigma_params[name], rel=0.2), name
    assert s.extras["covariance_kind"] == "sandwich"


def test_bad_input_is_named():
    p = preset("hrg")
    t, q = decay(p, seed=1, fs_hz=10.0, duration_s=60.0)
    with pytest.raises(ValueError, match="method='ml'"):
        identify_free_decay(t, *q.T, method="ml")
    with pytest.raises(ValueError, match="covariance='hac'"):
        identify_free_decay(t, *q.T, method="output-error", covariance="hac")
    with pytest.raises(FreeDecayFitError, match="max_iter=1"):
        identify_free_decay(t, *q.T, method="output-error", max_iter=1)
    with pytest.raises(ValueError, match="max_iter=0"):
        output_error_fit(t, q, z_of(p, "linear"), max_iter=0)
    with pytest.raises(ValueError, match="q0="):
        crlb_free_decay(duration_s=10.0, stream_hz=10.0, noise_sigma=1e-4, q0=np.zeros(4), params=truth(p))
    with pytest.raises(ValueError, match="lacks"):
        crlb_free_decay(duration_s=10.0, stream_hz=10.0, noise_sigma=1e-4, q0=Q0, params={"gamma": 1.0},
                        model="cubic")
    with pytest.raises(ValueError, match="noise_sigma"):
        crlb_free_decay(duration_s=10.0, stream_hz=10.0, noise_sigma=0.0, q0=Q0, params=truth(p))
    with pytest.raises(ValueError, match="non-finite"):
        bad = q.copy()
        bad[3, 1] = np.nan
        identify_free_decay(t, *bad.T, method="output-error")
    with pytest.raises(ValueError, match="rotation_basis has shape"):
        identify_free_decay(t, *q.T, method="output-error", rotation_basis=np.ones((5, 2)))
    _, phi, sens = linear_sensitivities(z_of(p, "linear"), Q0, 5, 0.1, params=())
    assert sens.shape == (5, 4, 0) and np.allclose(phi[0], np.eye(4))


def test_rotation_basis_removes_table_ripple_bias():
    """A table angle ripple of 1e-3 deg once and 5e-4 deg twice per revolution turns the measured
    wave (the simulator's ripple path): fitted as an output rotation it leaves every parameter
    within 3.3 standard errors, and the ripple's coefficients too."""
    p = preset("hrg")
    rate_dps, fs, n = 20.0, 100.0, 6000
    res = Resonator(p, seed=2, state=Q0)
    t = np.arange(1, n + 1) / fs
    ang = np.radians(rate_dps * t)
    dev = np.radians(1e-3 * np.sin(ang) + 5e-4 * np.sin(2 * ang))
    q = res.measure(res.step_block(n, 1.0 / fs, rate_rad_s=math.radians(rate_dps), ripple_angle_rad=dev))
    w = math.radians(rate_dps) * (t - t[0])
    basis = np.stack([np.cos(w), np.sin(w), np.cos(2 * w), np.sin(2 * w)], axis=1)
    oe = identify_free_decay(t - t[0], *q.T, method="output-error", rotation_basis=basis)
    tr = dict(zip(LINEAR_PARAM_NAMES, p.coefficients().zg(math.radians(rate_dps)), strict=True))
    for name in LINEAR_PARAM_NAMES:
        assert abs(oe.params[name] - tr[name]) < 3.3 * oe.sigma_params[name], name
    a1, a2 = math.radians(rate_dps * t[0]), math.radians(2 * rate_dps * t[0])  # sin(w + a) = sin w cos a + ...
    c_true = -2.0 * p.bryan_factor * np.radians([1e-3 * math.sin(a1), 1e-3 * math.cos(a1),
                                                 5e-4 * math.sin(a2), 5e-4 * math.cos(a2)])  # psi = -2 K dev
    se = np.sqrt(np.diag(oe.extras["covariance_full"])[-4:])
    assert np.all(np.abs(oe.extras["rotation_coefficients"] - c_true) < 3.3 * se), (oe.extras, c_true, se)
    assert abs(c_true[1]) > 3.5 * se[1]  # the once-per-rev ripple is well above the noise
