"""Self-calibration analysis (bench/analysis/selfcal.py) against closed-form synthetic cycles with
known truth (the channel models of docs/selfcal.md), and the coverage of its intervals."""

import math

import numpy as np
import pytest

from bench.analysis import selfcal as s

F0_HZ = 5500.0
GAMMA = 2.0 / 300.0
D, TH_TAU = 1.6e-4, math.radians(20.0)
DG = 1.5e-3
SPLIT_HZ, TH_W = 0.005, math.radians(10.0)
W = math.radians(0.05)  # precession command, rad/s: a 3600 s cycle
K = 0.277


def _cycle(seed: int, sigma_amp: float = 2e-6, sigma_f: float = 2e-6, dt: float = 1.0):
    """One forced-precession cycle (0 -> 90 deg -> 0 of wave angle) sampled every dt."""
    rng = np.random.default_rng(seed)
    half = math.radians(90.0) / W
    t = np.arange(0.0, 2 * half, dt)
    cmd = np.where(t < half, W, -W)
    th = np.where(t < half, W * t, W * (2 * half - t)) + 0.3
    bc, bs = D * math.cos(4 * TH_TAU), D * math.sin(4 * TH_TAU)
    amp = (GAMMA + (bc - GAMMA * DG / 2) * np.cos(4 * th) + bs * np.sin(4 * th) + 2 * DG * cmd * np.sin(4 * th)
           + sigma_amp * rng.standard_normal(len(t)))
    freq = 0.01 + SPLIT_HZ / 2 * np.cos(4 * (th - TH_W)) + sigma_f * rng.standard_normal(len(t))
    return t, th, cmd, amp, freq


def _fit(t, th, cmd, amp, freq, **kw):
    return s.fit_cycle(t, th, cmd, amp, freq, amplitude=1.0, f0_hz=F0_HZ, **kw)


TRUTH = {"gain_diff": DG, "q_factor": 2 * math.pi * F0_HZ / GAMMA, "delta_inv_tau": D,
         "theta_tau_deg": 20.0, "split_hz": SPLIT_HZ, "theta_w_deg": 10.0}


def test_identifies_the_closed_form_truth():
    f = _fit(*_cycle(1, sigma_amp=0.0, sigma_f=0.0))
    for name, truth in TRUTH.items():
        assert getattr(f, name).value == pytest.approx(truth, rel=1e-9, abs=1e-12), name


def test_drift_model_and_compensated_rate():
    """A wave turning under the command plus the model's drift: the compensated rate is the input."""
    t, th, cmd, amp, freq = _cycle(2, sigma_amp=0.0, sigma_f=0.0)
    f = _fit(t, th, cmd, amp, freq)
    dt = 1.0
    true_rate_dph = 3.0
    theta = np.zeros_like(t)
    theta[0] = 0.3
    for i in range(1, len(t)):
        d = f.drift_rad_s(np.array([theta[i - 1]]), np.array([cmd[i]]))[0]
        theta[i] = theta[i - 1] + (cmd[i] + d - K * math.radians(true_rate_dph / 3600.0)) * dt
    _tm, _th, plain = s.rate_dph(theta, t, cmd, K)
    _tm, thm, _ = s.rate_dph(theta, t, cmd, K)
    _tm, _th, comp = s.rate_dph(theta, t, cmd, K, f.drift_rad_s(thm, cmd[1:]))
    assert np.std(plain) > 15.0  # the drift, 29 deg/h amplitude, is in the plain rate
    assert np.max(np.abs(comp - true_rate_dph)) < 0.5  # Euler steps of the closed form, not noise
    assert abs(np.mean(comp) - true_rate_dph) < 0.01


def test_intervals_cover_in_a_seeded_monte_carlo():
    """White channel noise: the OLS covariance is the Cramer-Rao bound of the linear model; the 95 %
    intervals of every parameter cover the truth about 95 % of the time (200 seeded cycles)."""
    draws = 200
    hits = {n: 0 for n in TRUTH}
    for seed in range(draws):
        f = _fit(*_cycle(100 + seed, sigma_amp=2e-5, sigma_f=2e-5))
        for name, truth in TRUTH.items():
            lo, hi = getattr(f, name).ci
            hits[name] += lo <= truth <= hi
    for name, h in hits.items():
        assert 0.91 <= h / draws <= 0.99, (name, h / draws)


def test_bias_stability_of_white_noise_and_the_running_figures():
    rng = np.random.default_rng(5)
    n_dph = 0.52 * 10.0  # 0.52 deg/h over 100 s from 1 s samples of white noise
    rate = n_dph * rng.standard_normal(36000)
    bs = s.bias_stability_dph(rate, 1.0, 100.0)
    lo, hi = s.bias_stability_interval(bs, 360)
    assert lo < 0.52 < hi
    assert s.mean_since_start_dph(np.array([1.0, 3.0]))[-1] == 2.0
    assert s.integrated_angle_deg(np.full(3600, 1.0), 1.0)[-1] == pytest.approx(1.0)
    with pytest.raises(ValueError, match="fewer than two 100 s windows"):
        s.bias_stability_dph(rate[:150], 1.0, 100.0)


def test_gain_trend_and_bad_input():
    t_h = np.arange(20.0)
    g = 1500.0 + 20.0 * t_h
    g0, slope = s.gain_trend(t_h, g + np.random.default_rng(1).normal(0, 1.0, 20), np.full(20, 1.0))
    assert slope.ci[0] < 20.0 < slope.ci[1] and g0.ci[0] < 1500.0 < g0.ci[1]
    with pytest.raises(ValueError, match="too short"):
        _fit(*(a[:4] for a in _cycle(1)))
    assert s.cycle_bounds(np.r_[np.full(5, 1.0), np.full(5, -1.0), np.full(5, 1.0)]) == [(0, 10)]


def test_angle_error_fit_recovers_the_bounded_floor_and_its_mean_interval_covers():
    """Seeded 10 h records of the hrg-selfcal floor (small ARW + bounded angle wander): the fitted
    bounded std is near the truth and the mean after 10 h lies within +-1.96 of the fitted spread."""
    import dataclasses

    from simulators.physics.noise import NOISE_PRESETS, Environment, rad_s_to_dph

    nz = dataclasses.replace(NOISE_PRESETS["hrg-selfcal"], gain_x_ppm=0.0, gain_y_ppm=0.0,
                             gain_x_drift_ppm_h=0.0, gain_y_drift_ppm_h=0.0)
    bounded, covered, sds = [], 0, []
    for seed in range(20):
        r = Environment(nz, seed=seed, sample_period_s=1.0).rate_samples(36000) * rad_s_to_dph(1.0)
        model = s.fit_angle_error(s.integrated_angle_deg(r, 1.0), 1.0)
        bounded.append(math.sqrt(model.bounded_var_deg2))
        sd = model.mean_sd_dph(36000.0)
        sds.append(sd)
        covered += abs(float(np.mean(r))) <= 1.96 * sd
    assert np.median(bounded) == pytest.approx(nz.angle_wander_deg, rel=0.15)
    assert np.median(sds) == pytest.approx(float(nz.average_sd_dph(36000.0)), rel=0.25)
    assert covered >= 17  # 95 % of 20: P(< 17) = 1.6 %; seeded, measured 20


def test_angle_error_fit_of_white_rate_noise_is_an_angle_random_walk():
    rng = np.random.default_rng(4)
    r = rng.standard_normal(40000) * 0.6  # 0.01 deg/sqrt(h) sampled at 1 s: 0.6 deg/h per sample
    model = s.fit_angle_error(s.integrated_angle_deg(r, 1.0), 1.0)
    assert math.sqrt(model.arw2_deg2_s) * 60.0 == pytest.approx(0.01, rel=0.2)
    assert model.mean_sd_dph(36000.0) == pytest.approx(0.6 / math.sqrt(36000.0), rel=0.25)
    with pytest.raises(ValueError, match="too short"):
        s.fit_angle_error(np.zeros(20), 1.0)


def test_an_arw_fitted_on_its_bound_carries_a_one_sided_interval():
    """A record that a bounded angle error explains (no walk: a 0.01 deg Gauss-Markov wander with
    300 s correlation; seed 3 fits N = 0 exactly) still bounds N from above; that bound covers a
    true small walk in seeded records (Bonferroni over the lags: conservative)."""
    rng = np.random.default_rng(3)
    a = math.exp(-1.0 / 300.0)
    kicks = rng.standard_normal(7200) * 0.01 * math.sqrt(1 - a * a)
    wander = np.zeros(7200)
    for k in range(1, 7200):
        wander[k] = a * wander[k - 1] + kicks[k]
    value, (lo, hi) = s.fit_angle_error(wander, 1.0).arw_deg_rth()
    assert value == 0.0 and lo == 0.0 and 0.03 < hi < 0.08
    covered = 0
    for seed in range(20):
        r = np.random.default_rng(seed).standard_normal(7200) * 0.6  # N = 0.01 deg/sqrt(h)
        _, (lo, hi) = s.fit_angle_error(s.integrated_angle_deg(r, 1.0), 1.0).arw_deg_rth()
        covered += lo <= 0.01 <= hi
    assert covered >= 19
