"""The HRG damping estimators (bench.analysis.damping) against the simulator's truth.

Tolerances come from the Cramer-Rao bound of the same scenario (bench.analysis.damping_design):
a fit within 4 sigma of the truth fails by chance with probability < 1e-4, and every random
source is seeded, so the tests are deterministic."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bench.analysis import damping as dm
from bench.analysis.damping_design import DecayScenario, energy_bound
from bench.analysis.slow_model import state_from_elements
from simulators.physics.averaged import Resonator
from simulators.physics.params import preset
from simulators.world import World

HRG = preset("hrg")  # tau 300 s, D 1.6e-4 1/s, theta_tau 20 deg, split 5 mHz, noise 1e-4


def _decay(params, rate_dps: float, duration_s: float, stream_hz: float, *, seed: int = 0, k0: float = 0.0):
    """A free decay straight from the resonator model: (t, measured q, true q)."""
    res = Resonator(params, seed=seed)
    res.set_state(state_from_elements(1.0, k0, 0.3, 0.0))
    n = int(round(duration_s * stream_hz))
    q = res.step_block(n, 1.0 / stream_hz, rate_rad_s=math.radians(rate_dps))
    return np.arange(1, n + 1) / stream_hz, res.measure(q), q


def _bound(params, rate_dps, duration_s, stream_hz, k0=0.0):
    return energy_bound(
        DecayScenario(
            tau_s=params.tau_s, delta_inv_tau_per_s=params.delta_inv_tau_per_s, noise_sigma=params.noise_sigma,
            rate_dps=rate_dps, duration_s=duration_s, stream_hz=stream_hz, theta_tau_deg=params.theta_tau_deg,
            theta0_deg=math.degrees(0.3), quadrature=k0, split_hz=params.split_hz, theta_w_deg=params.theta_w_deg,
            bryan_factor=params.bryan_factor,
        )
    )


class _Recorder:
    """A tiny World device: holds the table rate and collects the measured slow variables."""

    def __init__(self, rate_dps: float) -> None:
        self.rate_dps = rate_dps
        self.t: list[np.ndarray] = []
        self.q: list[np.ndarray] = []

    def before_block(self, world, t_s, n, dt_s) -> None:
        world.case_rate_dps = self.rate_dps

    def after_block(self, world, block) -> None:
        self.t.append(block.t_s)
        self.q.append(block.q_meas)


def test_fit_on_world_decay_matches_truth_within_crlb():
    """Patent conditions on the World (500 deg/s, 300 s at 1 kHz): every method within 4 sigma
    of the truth, sigma the energy CRLB; the public result has the promised shape."""
    world = World(HRG, seed=11, sample_period_s=1e-3, max_block_s=1.0)
    world.resonator.set_state(state_from_elements(1.0, 0.0, 0.3, 0.0))
    rec = _Recorder(500.0)
    world.attach(rec)
    world.advance(300.0)
    t, q = np.concatenate(rec.t), np.concatenate(rec.q)
    bound = _bound(HRG, 500.0, 300.0, 1000.0)
    truth = HRG.truth()
    for method in dm.METHODS:
        fit = dm.fit_free_decay(t, q[:, 0], q[:, 1], q[:, 2], q[:, 3], method=method)
        assert set(fit.ci95) == {"theta_tau_deg", "delta_inv_tau_per_s", "tau_s"}
        assert 0.0 <= fit.theta_tau_deg < 90.0 and fit.delta_inv_tau_per_s >= 0.0
        assert abs(fit.delta_inv_tau_per_s - truth["delta_inv_tau_per_s"]) < 4 * bound.std_delta_inv_tau_per_s
        assert abs(fit.theta_tau_deg - truth["theta_tau_deg"]) < 4 * bound.std_theta_tau_deg
        assert abs(fit.tau_s - truth["tau_s"]) < 4 * bound.std_tau_s
        lo, hi = fit.ci95["delta_inv_tau_per_s"]
        assert lo < fit.delta_inv_tau_per_s < hi
        assert fit.noise_sigma == pytest.approx(HRG.noise_sigma, rel=0.05)  # 3e5 samples: ~0.2 % scatter
        assert fit.converged
    # derived figures: Q = pi f0 tau, drift (D/4)/K -> about 29.8 deg/h for the preset
    assert fit.q_factor(HRG.f0_hz) == pytest.approx(HRG.q_factor, rel=1e-3)
    exact_dph = math.degrees(fit.delta_inv_tau_per_s / 4 / HRG.bryan_factor) * 3600
    assert fit.drift_amplitude_dph(HRG.bryan_factor) == pytest.approx(exact_dph)
    assert fit.energy_fit.shape == fit.residuals_ln_e.shape == t.shape


def test_gauss_newton_from_zero_agrees_with_closed_form():
    """The patent's start at D = 0 converges (b_c, b_s parametrisation) to the weighted
    closed-form answer: the two are the same estimator to first order, so within 0.05 sigma."""
    t, qm, _ = _decay(HRG, 100.0, 200.0, 200.0, seed=3)
    ll = dm.fit_free_decay_q(t, qm, method="log-linear")
    gn = dm.fit_free_decay_q(t, qm, method="gauss-newton", start="zero")
    assert gn.converged and gn.iterations < 10
    for name in ("delta_inv_tau_per_s", "theta_tau_deg", "tau_s"):
        assert abs(getattr(gn, name) - getattr(ll, name)) < 0.05 * ll.std[name]


@pytest.mark.parametrize("method", ["gauss-newton", "log-linear"])
def test_sequential_fit_converges_to_batch(method):
    """Blocks of 1 s arriving one after the other: the running estimate ends at the batch fit
    (within 0.1 sigma) and its interval shrinks as data arrive."""
    t, qm, _ = _decay(HRG, 200.0, 120.0, 500.0, seed=5)
    batch = dm.fit_free_decay_q(t, qm, method="log-linear")
    seq = dm.SequentialDampingFit(method=method)
    widths = []
    for i in range(0, t.size, 500):
        est = seq.update(t[i : i + 500], *qm[i : i + 500].T)
        lo, hi = est.ci95["delta_inv_tau_per_s"]
        widths.append(hi - lo)
    assert seq.n_samples == t.size
    assert widths[-1] < 0.5 * widths[10]  # 11 s -> 120 s of data: about 0.36x
    for name in ("delta_inv_tau_per_s", "theta_tau_deg", "tau_s"):
        assert abs(getattr(est, name) - getattr(batch, name)) < 0.1 * batch.std[name]
    # the running integrals across block boundaries are the batch ones (same exact step rule)
    full = seq.result()
    reg = dm.decay_regressors(t, *qm.T)
    assert np.allclose(-reg.x[:, 2], dm.decay_regressors(t, *qm.T).c_int_s)
    assert np.allclose(full.theta_rad, 0.25 * reg.phi_rad, atol=1e-12, rtol=0)
    assert full.energy_fit.shape == t.shape
    assert est.ci95["delta_inv_tau_per_s"][1] - est.ci95["delta_inv_tau_per_s"][0] == pytest.approx(
        batch.ci95["delta_inv_tau_per_s"][1] - batch.ci95["delta_inv_tau_per_s"][0], rel=0.05
    )


def test_exact_step_integrals_at_slow_stream():
    """PHYSICS pitfall (c): at a 10 Hz stream and 500 deg/s, 4 theta turns ~1 rad per sample; the
    exact per-step integrals recover D from noise-free data to 0.1 % (the trapezoid rule: +8 %)."""
    p = HRG.with_(noise_sigma=0.0, split_hz=0.0)
    t, _, q = _decay(p, 500.0, 300.0, 10.0)
    fit = dm.fit_free_decay_q(t, q)
    assert fit.delta_inv_tau_per_s == pytest.approx(p.delta_inv_tau_per_s, rel=1e-3)
    assert fit.theta_tau_deg == pytest.approx(p.theta_tau_deg, abs=0.05)


def test_exact_model_removes_split_quadrature_bias():
    """5 deg/s with a 0.05 rad/s split and 0.02 quadrature (PHYSICS section 3): the patent's
    cos 4 theta model is biased by several % of D; the quadrature-aware model is not (< 0.3 %)."""
    p = HRG.with_(noise_sigma=0.0, split_hz=0.05 / (2 * math.pi), delta_inv_tau_per_s=2e-4)
    t, _, q = _decay(p, 5.0, 300.0, 200.0, k0=0.02)
    patent = dm.fit_free_decay_q(t, q, model="patent")
    exact = dm.fit_free_decay_q(t, q, model="exact")
    assert abs(patent.delta_inv_tau_per_s / 2e-4 - 1) > 0.03
    assert exact.delta_inv_tau_per_s == pytest.approx(2e-4, rel=3e-3)
    assert exact.theta_tau_deg == pytest.approx(p.theta_tau_deg, abs=0.2)


def test_interval_coverage_and_efficiency_monte_carlo():
    """200 seeded noise draws on one decay (the noise is additive, so the trajectory is shared):
    the 95 % intervals cover the truth 91-99 % of the time (binomial sd 1.5 %), the scatter is
    within 0.85-1.2 of the energy CRLB and the bias under 0.25 sigma (+- 0.07 sampling)."""
    p = HRG.with_(split_hz=0.0)
    rate, dur, fs = 100.0, 150.0, 100.0
    t, _, q = _decay(p, rate, dur, fs)
    bound = _bound(p, rate, dur, fs)
    rng = np.random.default_rng(123)
    d_hat, cover = [], {k: 0 for k in dm.CI_NAMES}
    truth = p.truth()
    n = 200
    for _ in range(n):
        qm = q + rng.normal(0.0, p.noise_sigma, q.shape)
        fit = dm.fit_free_decay_q(t, qm)
        d_hat.append(fit.delta_inv_tau_per_s)
        for k in dm.CI_NAMES:
            lo, hi = fit.ci95[k]
            cover[k] += lo <= truth[k] <= hi
    d_hat = np.asarray(d_hat)
    for k in dm.CI_NAMES:
        assert 0.91 <= cover[k] / n <= 0.99, (k, cover[k] / n)
    ratio = d_hat.std(ddof=1) / bound.std_delta_inv_tau_per_s
    assert 0.85 < ratio < 1.2
    assert abs(d_hat.mean() - truth["delta_inv_tau_per_s"]) < 0.25 * d_hat.std(ddof=1)


def test_fit_angle_drift_recovers_harmonic():
    """rate = c + A sin 4(theta - phi) + noise: A and phi to within the noise (4 sigma)."""
    rng = np.random.default_rng(7)
    theta = np.linspace(0, 2 * math.pi, 5000)
    amp, phase, c = 2e-5, math.radians(20.0), 1e-6
    rate = c + amp * np.sin(4 * (theta - phase)) + rng.normal(0, 1e-6, theta.size)
    fit = dm.fit_angle_drift(theta, rate)
    a_hat, ph_hat = fit
    assert a_hat == pytest.approx(amp, abs=4 * 1e-6 * math.sqrt(2 / theta.size))
    assert math.degrees(ph_hat) == pytest.approx(20.0, abs=0.1)
    assert fit.offset_rad_s == pytest.approx(c, abs=1e-7)
    assert fit.amplitude_ci95[0] < amp < fit.amplitude_ci95[1]
    assert fit.amplitude_dph(0.277) == pytest.approx(math.degrees(a_hat / 0.277) * 3600)


def test_damping_drift_phase_is_the_damping_axis():
    """The wave's drift (D/4) sin 4(theta - theta_tau) (PHYSICS section 2): the fitted phase of the
    angle drift is theta_tau, so the two helpers speak the same convention."""
    theta = np.linspace(0, math.pi, 2000)
    rate = 0.25 * 1.6e-4 * np.sin(4 * (theta - math.radians(20.0)))
    amp, ph = dm.fit_angle_drift(theta, rate)
    assert amp == pytest.approx(4e-5, rel=1e-9) and math.degrees(ph) == pytest.approx(20.0, abs=1e-6)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"cx": np.ones(5)}, "cx has 5 samples"),
        ({"t_s": np.zeros(20)}, "strictly increasing"),
        ({"sy": np.full(20, np.nan)}, "sy contains non-finite"),
    ],
)
def test_bad_input_is_named(kwargs, match):
    data = {"t_s": np.arange(20.0), "cx": np.ones(20), "sx": np.zeros(20), "cy": np.zeros(20), "sy": np.zeros(20)}
    data.update(kwargs)
    with pytest.raises(dm.DampingFitError, match=match):
        dm.fit_free_decay(**data)


def test_bad_options_and_short_data():
    z = np.zeros(5)
    with pytest.raises(dm.DampingFitError, match="at least 8"):
        dm.fit_free_decay(np.arange(5.0), z + 1, z, z, z)
    t, qm, _ = _decay(HRG, 500.0, 1.0, 100.0)
    with pytest.raises(dm.DampingFitError, match="method='newton'"):
        dm.fit_free_decay_q(t, qm, method="newton")
    with pytest.raises(dm.DampingFitError, match="model='cubic'"):
        dm.fit_free_decay_q(t, qm, model="cubic")
    seq = dm.SequentialDampingFit()
    seq.update(t[:50], *qm[:50].T)
    with pytest.raises(dm.DampingFitError, match="not after the previous sample"):
        seq.update(t[:50], *qm[:50].T)
    with pytest.raises(ValueError, match="theta_rad has 3 samples"):
        dm.fit_angle_drift(np.zeros(3), np.zeros(4))


@pytest.mark.parametrize("d_sigmas", [0.0, 1.5])
def test_delta_interval_keeps_coverage_near_zero(d_sigmas):
    """D = 0 and D = 1.5 standard errors (150 seeded noise draws on one decay each): the D interval
    covers the truth 89-100 % of the time (binomial sd 1.8 %); the old |b| +- 1.96 sd interval
    covered P(chi2_2 <= 3.84) = 85 % at D = 0 (test_delta_interval_unit shows it on draws)."""
    rate, dur, fs = 100.0, 60.0, 10.0
    p0 = HRG.with_(split_hz=0.0, delta_inv_tau_per_s=0.0)
    sd = _bound(p0.with_(delta_inv_tau_per_s=1e-6), rate, dur, fs).std_b_per_s / math.sqrt(2.0)
    p = p0.with_(delta_inv_tau_per_s=d_sigmas * sd)
    t, _, q = _decay(p, rate, dur, fs)
    rng = np.random.default_rng(321)
    cover, n = 0, 150
    for _ in range(n):
        fit = dm.fit_free_decay_q(t, q + rng.normal(0.0, p.noise_sigma, q.shape))
        lo, hi = fit.ci95["delta_inv_tau_per_s"]
        assert 0.0 <= lo <= fit.delta_inv_tau_per_s <= hi
        cover += lo <= p.delta_inv_tau_per_s <= hi
    assert 0.89 <= cover / n <= 1.0, cover / n


def test_delta_interval_unit():
    """Gaussian damping vectors (anisotropic covariance, random axis): 95 % coverage at D = 0 and
    D = 2 sd (250 draws, 91-99 %), where the naive interval covers about 85 % at D = 0; far from
    zero it is the delta-method interval."""
    rng = np.random.default_rng(5)
    cov = np.array([[1.0, 0.2], [0.2, 1.8]]) * 1e-12
    for d_true, naive_max in ((0.0, 0.9), (2e-6, 1.0)):
        hit = naive = 0
        for _ in range(250):
            ang = rng.uniform(0.0, 2.0 * math.pi)
            b = rng.multivariate_normal(d_true * np.array([math.cos(ang), math.sin(ang)]), cov)
            lo, hi = dm.delta_interval(b, cov)
            hit += lo <= d_true <= hi
            d = math.hypot(*b)
            g = b / d
            sd = math.sqrt(g @ cov @ g)
            naive += max(0.0, d - 1.96 * sd) <= d_true <= d + 1.96 * sd
        assert 0.91 <= hit / 250 <= 0.99, (d_true, hit / 250)
        assert naive / 250 <= naive_max
    b = np.array([3e-4, 4e-4])
    lo, hi = dm.delta_interval(b, cov)
    sd = math.sqrt(b @ cov @ b) / 5e-4
    assert lo == pytest.approx(5e-4 - 1.959964 * sd, rel=1e-9) and hi == pytest.approx(5e-4 + 1.959964 * sd, rel=1e-9)
