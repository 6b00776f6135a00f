"""Free-decay identification (Simpson regressors, batch and recursive LS) against the simulator's
`Resonator` truth, and the coverage of its intervals by seeded Monte Carlo."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bench.analysis.maslov import identify_free_decay
from bench.analysis.slow_model import LINEAR_PARAM_NAMES, state_from_elements
from simulators.physics.averaged import Resonator
from simulators.physics.params import ResonatorParams, preset

RATE_RAD_S = math.radians(20.0)  # the table spins so the wave sweeps all angles (b and nu separate)


def decay(params: ResonatorParams, *, seed: int, fs_hz: float, duration_s: float, rate_rad_s: float = RATE_RAD_S):
    """Seeded free decay of a standing wave from theta = 17 deg: (t_s, measured q (N+1, 4))."""
    q0 = state_from_elements(1.0, 0.02, math.radians(17.0))
    res = Resonator(params, seed=seed, state=q0)
    n = int(round(duration_s * fs_hz))
    traj = np.vstack([q0, res.step_block(n, 1.0 / fs_hz, rate_rad_s=rate_rad_s)])
    return np.arange(n + 1) / fs_hz, res.measure(traj)


def truth(params: ResonatorParams, rate_rad_s: float = RATE_RAD_S) -> dict[str, float]:
    c = params.coefficients()
    out = dict(zip(LINEAR_PARAM_NAMES, c.zg(rate_rad_s), strict=True))
    out.update(xi=c.xi, kappa=c.kappa)
    return out


@pytest.fixture(scope="module")
def hrg_record():
    return decay(preset("hrg"), seed=11, fs_hz=100.0, duration_s=300.0)


def test_hrg_decay_recovers_the_resonator_within_the_corrected_interval(hrg_record):
    """Truth: the preset's coefficients at 20 deg/s.  Each estimate within its 99.9 % band
    (3.3 standard errors, so 8 parameters pass with overwhelming probability under a correct
    interval); derived quantities close to the preset's physical values."""
    t, q = hrg_record
    p = preset("hrg")
    res = identify_free_decay(t, *q.T, model="linear", natural_freq_hz=p.f0_hz, bryan_factor=p.bryan_factor)
    tr = truth(p)
    for name in LINEAR_PARAM_NAMES:
        assert abs(res.params[name] - tr[name]) < 3.3 * res.sigma_params[name], name
    assert res.derived["Q"] == pytest.approx(p.q_factor, rel=1e-3)
    assert res.derived["split_hz"] == pytest.approx(p.split_hz, rel=1e-3)
    assert res.derived["damping_anisotropy_per_s"] == pytest.approx(2 * p.delta_inv_tau_per_s, rel=0.05)
    assert math.degrees(res.derived["beta_rad"]) == pytest.approx(p.theta_tau_deg, abs=1.0)
    assert res.derived["zero_rate_dps"] == pytest.approx(20.0, rel=1e-4)
    assert res.noise_sigma == pytest.approx(p.noise_sigma, rel=0.02)


def test_recursive_equals_batch(hrg_record):
    """The paper's 4x4-block recursion gives the batch answer: to 1e-6 of a standard error."""
    t, q = hrg_record
    t, q = t[:6001], q[:6001]  # 60 s keeps the Python loop short
    batch = identify_free_decay(t, *q.T, model="linear")
    rec = identify_free_decay(t, *q.T, model="linear", recursive=True)
    for name in LINEAR_PARAM_NAMES:
        assert abs(rec.params[name] - batch.params[name]) < 1e-6 * batch.sigma_params[name], name
    scale = np.outer(np.sqrt(np.diag(batch.covariance)), np.sqrt(np.diag(batch.covariance)))
    np.testing.assert_allclose(rec.covariance / scale, batch.covariance / scale, atol=1e-6)
    assert rec.method == "free_decay_recursive"


def test_textbook_interval_is_far_too_wide_for_gamma_and_nu(hrg_record):
    t, q = hrg_record
    res = identify_free_decay(t, *q.T, model="linear")
    for name in ("gamma", "nu"):
        lo, hi = res.ci95_textbook[name]
        clo, chi = res.ci95[name]
        assert (hi - lo) > 20 * (chi - clo), name


def test_cubic_decay_identifies_xi():
    """A nonlinear resonator (xi 0.5 1/s, tau 2 s) decaying for 6 s: xi and gamma within the
    99.9 % band of the corrected interval; the linear model's residual sigma is larger."""
    p = ResonatorParams(f0_hz=5500.0, tau_s=2.0, delta_inv_tau_per_s=0.05, theta_tau_deg=25.0, split_hz=0.01,
                        theta_w_deg=5.0, xi_per_s=0.5, noise_sigma=1e-4)
    t, q = decay(p, seed=3, fs_hz=200.0, duration_s=6.0)
    res = identify_free_decay(t, *q.T, model="cubic")
    tr = truth(p)
    for name in ("gamma", "xi", "b_c", "h_c"):
        assert abs(res.params[name] - tr[name]) < 3.3 * res.sigma_params[name], name
    lin = identify_free_decay(t, *q.T, model="linear")
    assert lin.sigma > 1.05 * res.sigma


def test_interval_coverage_monte_carlo_small():
    """30 seeded 60 s decays at 100 Hz (HRG preset): the corrected intervals cover the truth about
    95 % of the time (30 x 8 intervals; band 0.88..1.0), the textbook ones essentially always."""
    p = preset("hrg")
    tr = truth(p)
    hits = text_hits = total = 0
    for seed in range(30):
        t, q = decay(p, seed=100 + seed, fs_hz=100.0, duration_s=60.0)
        res = identify_free_decay(t, *q.T, model="linear")
        for name in LINEAR_PARAM_NAMES:
            lo, hi = res.ci95[name]
            tlo, thi = res.ci95_textbook[name]
            hits += lo <= tr[name] <= hi
            text_hits += tlo <= tr[name] <= thi
            total += 1
    assert 0.88 <= hits / total <= 1.0
    assert text_hits / total > 0.99


def test_bad_input_is_rejected(hrg_record):
    t, q = hrg_record
    with pytest.raises(ValueError, match="model='septic'"):
        identify_free_decay(t, *q.T, model="septic")
    t_bad = t.copy()
    t_bad[10] += 0.003
    with pytest.raises(ValueError, match="uniformly increasing"):
        identify_free_decay(t_bad, *q.T)
    with pytest.raises(ValueError, match="need more than 8"):
        identify_free_decay(t[:3], *q[:3].T)
    with pytest.raises(ValueError, match="n_init_blocks=2"):
        identify_free_decay(t[:500], *q[:500].T, recursive=True, n_init_blocks=2)


def _direct_sandwich(t: np.ndarray, q: np.ndarray, model: str) -> tuple[np.ndarray, np.ndarray, float]:
    """The former algorithm written out: materialised Simpson regressors X, normal equations, and
    F_j = X_{j-1} - X_{j+1} - h3 J_j^T (X_{j-1} + 4 X_j + X_{j+1}) with J_j from nonlinear_jacobian."""
    from bench.analysis.maslov_decay import simpson_regressors
    from bench.analysis.maslov_terms import nonlinear_jacobian
    from bench.analysis.slow_model import linear_matrix

    dt = float(t[1] - t[0])
    x, y = simpson_regressors(q, dt, model)
    k = x.shape[-1]
    x2 = x.reshape(-1, k)
    c = np.linalg.inv(x2.T @ x2)
    z = np.linalg.solve(x2.T @ x2, x2.T @ y.reshape(-1))
    jac = linear_matrix(z[:8]) + 0.5 * nonlinear_jacobian(q, model, z[8:])
    xp = np.concatenate([np.zeros((2, 4, k)), x, np.zeros((2, 4, k))])
    f = xp[:-2] - xp[2:] - (dt / 3.0) * np.einsum("jba,jbk->jak", jac, xp[:-2] + 4.0 * xp[1:-1] + xp[2:])
    meat = np.einsum("jak,jal->kl", f, f)
    h3, eye = dt / 3.0, np.eye(4)
    lnorm = float(np.sum((eye - h3 * jac[2:]) ** 2) + np.sum((4 * h3 * jac[1:-1]) ** 2)
                  + np.sum((eye + h3 * jac[:-2]) ** 2))
    return z, c @ meat @ c, lnorm


@pytest.mark.parametrize("model", ["cubic", "quintic"])
def test_moment_fit_equals_the_direct_algorithm(model):
    """The moment-based batch fit and the closed-form Jacobian sandwich equal the direct formulas
    (materialised X, per-sample J from nonlinear_jacobian): parameters to 1e-9 of a standard error,
    covariance to 1e-9 relative (rounding only; the normal matrix here has condition ~1e5)."""
    from bench.analysis import maslov_decay as md

    p = ResonatorParams(f0_hz=5500.0, tau_s=2.0, delta_inv_tau_per_s=0.05, theta_tau_deg=25.0, split_hz=0.01,
                        theta_w_deg=5.0, xi_per_s=0.5, kappa_per_s=0.2, noise_sigma=1e-4)
    t, q = decay(p, seed=5, fs_hz=200.0, duration_s=6.0)
    res = identify_free_decay(t, *q.T, model=model)
    z, meat_cov, lnorm = _direct_sandwich(t, q, model)
    se = np.sqrt(np.diag(res.covariance))
    np.testing.assert_array_less(np.abs(res.vector() - z) / se, 1e-9)
    fit = md._general_fit(q, float(t[1] - t[0]), model, False, None)
    assert fit["lnorm"] == pytest.approx(lnorm, rel=1e-12)
    cov_fast = fit["c"] @ fit["meat"] @ fit["c"]
    scale = np.outer(np.sqrt(np.diag(meat_cov)), np.sqrt(np.diag(meat_cov)))
    np.testing.assert_allclose(cov_fast / scale, meat_cov / scale, atol=1e-9)


@pytest.mark.parametrize("model", ["linear", "quintic"])
def test_chunked_recursion_equals_the_4x4_loop(hrg_record, model):
    """recursive_lsq in chunks of 4x4 blocks (push-through update) equals the literal one-block loop
    and the batch answer: z to 1e-6 of the batch's textbook standard error (sqrt of diag P), P to
    1e-6 of the batch's.  The literal loop's own P drifts from the batch's by rounding (~5e-4
    relative for quintic on this weakly nonlinear record: kappa is barely identifiable), so P is
    checked against the loop at 1e-3."""
    from bench.analysis.maslov_decay import recursive_lsq, simpson_regressors

    t, q = hrg_record
    x, y = simpson_regressors(q[:3001], float(t[1] - t[0]), model)
    x2 = x.reshape(-1, x.shape[-1])
    z_batch = np.linalg.solve(x2.T @ x2, x2.T @ y.reshape(-1))
    sd = np.sqrt(np.diag(np.linalg.inv(x2.T @ x2)))
    z_loop, p_loop = recursive_lsq(x, y, 100)
    for chunk in (7, 256, 100000):
        z_chunk, p_chunk = recursive_lsq(x, y, 100, chunk_blocks=chunk)
        np.testing.assert_array_less(np.abs(z_chunk - z_loop) / sd, 1e-6)
        np.testing.assert_array_less(np.abs(z_chunk - z_batch) / sd, 1e-6)
        p_batch = np.linalg.inv(x2.T @ x2)
        np.testing.assert_allclose(p_chunk / np.outer(sd, sd), p_batch / np.outer(sd, sd), atol=1e-6)
        np.testing.assert_allclose(p_chunk / np.outer(sd, sd), p_loop / np.outer(sd, sd), atol=1e-3)
    with pytest.raises(ValueError, match="chunk_blocks=0"):
        recursive_lsq(x, y, 100, chunk_blocks=0)


def test_short_record_recursive_starts_on_what_there_is():
    """A 30-sample record: the default batch start is clamped to the blocks available, so the
    recursive answer exists and equals the batch one (nothing left to recurse over)."""
    from bench.analysis.maslov import identify_free_decay

    rng = np.random.default_rng(5)
    t = np.arange(30) * 0.01
    q = np.exp(-0.5 * t)[:, None] * np.array([1.0, 0.2, 0.3, -0.1]) + 1e-4 * rng.standard_normal((30, 4))
    batch = identify_free_decay(t, *q.T)
    rec = identify_free_decay(t, *q.T, recursive=True)
    for name in batch.params:
        assert rec.params[name] == pytest.approx(batch.params[name], rel=1e-6, abs=1e-9), name
