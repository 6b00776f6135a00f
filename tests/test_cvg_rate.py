"""bench.analysis.cvg_rate on synthetic series with known truth: the scale factor, bias,
nonlinearity, asymmetry, static bias and turn-on repeatability come back, and their 95 % intervals
cover the truth as often as they say (seeded Monte Carlo, kept small: 400 draws, so a coverage
within [0.92, 0.98] is about 2.3 binomial sigma around 0.95; benchmarks/cvg_rate_coverage.py runs
the larger study)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bench.analysis.cvg_rate import (
    earth_rate_projection_dph,
    fit_scale_factor,
    static_bias,
    turn_on_repeatability,
    window_distortion,
    window_output,
)

RATES = np.concatenate([np.linspace(-20, 20, 9), np.linspace(20, -20, 9)])


def _series(rng, *, sf=0.9972, bias_dph=29.3, noise=2e-4, asym_ppm=0.0, bow=0.0, drift=None):
    """Window means of a rate output: sf (1 + asym/2 sign) rate + bias + bow rate^2 + noise."""
    gain = sf * (1 + 0.5e-6 * asym_ppm * np.sign(RATES))
    y = gain * (RATES + bias_dph / 3600.0) + bow * RATES**2 + rng.normal(0, noise, len(RATES))
    basis = None
    if drift is not None:  # whole-angle: a drift c cos 4 theta + s sin 4 theta, theta spread over the windows
        th = rng.uniform(0, 2 * math.pi, len(RATES))
        basis = np.column_stack([np.cos(th), np.sin(th)])
        y = y + basis @ np.asarray(drift)
    return y, basis


def test_recovers_a_linear_series_exactly_without_noise():
    y, _ = _series(np.random.default_rng(0), noise=0.0)
    fit = fit_scale_factor(RATES, y + 1e-15 * np.arange(len(y)))  # a hair of scatter keeps sigma > 0
    assert fit.scale_factor == pytest.approx(0.9972, rel=1e-12)
    assert fit.bias_dph == pytest.approx(29.3, abs=1e-8)
    assert fit.nonlinearity_ppm < 1e-6 and abs(fit.asymmetry_ppm) < 1e-6


def test_earth_rate_is_removed_from_the_bias():
    y, _ = _series(np.random.default_rng(1), bias_dph=29.3 + 11.0)
    fit = fit_scale_factor(RATES, y, earth_rate_dph=11.0)
    assert fit.bias_dph == pytest.approx(29.3, abs=2.0)


def test_nonlinearity_and_asymmetry_are_seen_when_present():
    """A bow 2e-5 rate^2 (400 ppm of full scale at R = 20) and a 500 ppm asymmetry: both found,
    their intervals excluding zero; the truth of the asymmetry inside its interval."""
    rng = np.random.default_rng(2)
    y, _ = _series(rng, bow=2e-5, noise=5e-5)
    fit = fit_scale_factor(RATES, y)
    assert fit.nonlinearity_ppm_ci95[0] > 0
    y, _ = _series(rng, asym_ppm=500.0, noise=5e-5)
    fit = fit_scale_factor(RATES, y)
    lo, hi = fit.asymmetry_ppm_ci95
    assert lo <= 500.0 <= hi and lo > 0


def test_whole_angle_drift_is_fitted_apart():
    """-K output with a 30 deg/h (in output units 0.0023 deg/s) 4-theta drift spread over the windows."""
    rng = np.random.default_rng(3)
    y, basis = _series(rng, sf=-0.277, bias_dph=0.0, drift=(0.0023, -0.001), noise=5e-5)
    fit = fit_scale_factor(RATES, y, drift_basis=basis)
    assert fit.scale_factor_ci95[0] <= -0.277 <= fit.scale_factor_ci95[1]
    assert fit.bias_dph_ci95[0] <= 0.0 <= fit.bias_dph_ci95[1]
    assert fit.drift_terms == pytest.approx((0.0023, -0.001), abs=3e-4)


def test_scale_factor_intervals_cover_at_their_level():
    rng = np.random.default_rng(4)
    hits = np.zeros(4)
    n = 400
    for _ in range(n):
        y, _ = _series(rng)
        f = fit_scale_factor(RATES, y)
        hits += [f.scale_factor_ci95[0] <= 0.9972 <= f.scale_factor_ci95[1],
                 f.bias_dph_ci95[0] <= 29.3 <= f.bias_dph_ci95[1],
                 f.asymmetry_ppm_ci95[0] <= 0.0 <= f.asymmetry_ppm_ci95[1],
                 f.nonlinearity_ppm_ci95[0] <= 0.0]  # simultaneous (Bonferroni): at least 95 %
    cover = hits / n
    assert np.all(cover[:3] >= 0.92) and np.all(cover[:3] <= 0.98), cover
    assert cover[3] >= 0.93, cover


def test_static_bias_and_its_interval():
    """Force-to-rebalance: white rate noise (0.01 deg/s a sample at 100 Hz) about 29.3 deg/h;
    whole-angle: an angle turning at -K times the bias with white angle noise."""
    rng = np.random.default_rng(5)
    t = np.arange(6000) / 100.0
    hits_ftr = hits_wa = 0
    n = 300
    for _ in range(n):
        out = 0.9972 * 29.3 / 3600 + rng.normal(0, 0.01, len(t))
        b = static_bias(t, out, mode="force-to-rebalance", scale_factor=0.9972)
        hits_ftr += b.ci95[0] <= 29.3 <= b.ci95[1]
        ang = -0.277 * 29.3 / 3600 * t + rng.normal(0, 1e-3, len(t))
        b = static_bias(t, ang, mode="whole-angle", scale_factor=-0.277)
        hits_wa += b.ci95[0] <= 29.3 <= b.ci95[1]
    assert 0.91 <= hits_ftr / n <= 0.99 and 0.91 <= hits_wa / n <= 0.99, (hits_ftr, hits_wa)


def test_window_output_by_mode():
    t = np.linspace(0, 10, 1001)
    ang = 5.0 - 2.77 * t
    out, c4, s4 = window_output(t, np.full_like(t, 3.0), ang, "whole-angle")
    assert out == pytest.approx(-2.77)
    w = t * (10 - t)  # the slope's parabolic weight
    assert c4 == pytest.approx(np.sum(w * np.cos(np.radians(4 * ang))) / w.sum())
    assert window_output(t, np.full_like(t, 3.0), ang, "whole-angle", 1.0)[0] == pytest.approx(-2.77)
    assert window_output(t, np.full_like(t, 3.0), ang, "force-to-rebalance")[0] == pytest.approx(3.0)


def test_window_rate_and_its_drift_regressors_are_weighted_alike():
    """A wave turning at -5.54 deg/s plus a drift c cos 4 theta + s sin 4 theta, integrated finely
    over 21 s (1.3 periods of 4 theta): each whole-angle estimator (slope; boxes of 1 s at the ends)
    equals -5.54 + c C + s S with its own regressors (C, S) to 1e-6 deg/s (0.2 ppm), where a plain
    mean of cos 4 theta with the slope misses by ~1e-4 (the bias the weighting removes)."""
    dt, c, s = 0.01, -0.0022, 0.0004
    t = np.arange(0.0, 21.0 + 1e-9, dt)
    th = np.empty_like(t)
    th[0] = 10.0
    for i in range(1, len(t)):
        r = math.radians(th[i - 1])
        th[i] = th[i - 1] + dt * (-5.54 + c * math.cos(4 * r) + s * math.sin(4 * r))
    for box in (0.0, 1.0):
        rate, c4, s4 = window_output(t, np.zeros_like(t), th, "whole-angle", box)
        assert rate == pytest.approx(-5.54 + c * c4 + s * s4, abs=1e-6)
    plain = np.radians(4 * th)
    slope = window_output(t, np.zeros_like(t), th, "whole-angle")[0]
    assert abs(slope - (-5.54 + c * np.mean(np.cos(plain)) + s * np.mean(np.sin(plain)))) > 1e-5


def test_turn_on_repeatability_removes_the_records_noise():
    """Turn-on spread 2 deg/h, each record's bias known to 0.5 deg/h: the spread's interval
    covers 2 about 95 % of the time (8 turn-ons), and with no spread the interval reaches 0."""
    rng = np.random.default_rng(6)
    n_turn, hits, n = 8, 0, 400
    for _ in range(n):
        b = 29.3 + rng.normal(0, 2.0, n_turn) + rng.normal(0, 0.5, n_turn)
        r = turn_on_repeatability(b, np.full(n_turn, 0.5))
        hits += r.ci95[0] <= 2.0 <= r.ci95[1]
    assert 0.92 <= hits / n <= 0.98, hits
    r = turn_on_repeatability(29.3 + rng.normal(0, 0.5, 3), np.full(3, 0.5))
    assert r.ci95[0] == 0.0
    with pytest.raises(ValueError, match="2 or more"):
        turn_on_repeatability(np.array([1.0]), np.array([0.1]))


def test_earth_rate_projection():
    lat = 48.0
    assert earth_rate_projection_dph(lat, elevation_deg=90.0) == pytest.approx(15.041067 * math.sin(math.radians(lat)))
    assert earth_rate_projection_dph(lat, 0.0, 0.0) == pytest.approx(15.041067 * math.cos(math.radians(lat)))
    assert earth_rate_projection_dph(lat, 90.0, 0.0) == pytest.approx(0.0, abs=1e-12)


def test_window_distortion_is_what_the_window_rate_reads_from_a_4theta_angle_distortion():
    """A wave turning at -5.54 deg/s over 19 s read as theta + a sin 4 theta + b cos 4 theta (unequal
    pickoff gains): each whole-angle estimator (slope; boxes of 1 s) reads -5.54 + a A + b B with
    (A, B) = window_distortion, to 1e-6 deg/s (the basis is taken at the read angle: second order in a);
    unfitted, a = -0.0086 deg puts it over 3e-5 deg/s off."""
    t = np.arange(0.0, 19.0 + 1e-9, 0.01)
    th = 10.0 - 5.54 * t
    a, b = -0.0086, 0.002
    r4 = np.radians(4 * th)
    read = th + a * np.sin(r4) + b * np.cos(r4)
    for box in (0.0, 1.0):
        rate = window_output(t, np.zeros_like(t), read, "whole-angle", box)[0]
        big_a, big_b = window_distortion(t, read, box)
        assert rate == pytest.approx(-5.54 + a * big_a + b * big_b, abs=1e-6)
        assert abs(rate + 5.54) > 3e-5


def test_scale_factor_intervals_hold_a_bias_wandering_from_the_turn_on():
    """Window errors a random walk of the bias from the turn-on (rate random walk) plus a little
    white noise, at sim-hrg-wa's window times: with t_mid_s the scale factor's and the bias's
    intervals cover about 95 % of 400 series; ordinary least squares (independent errors) covers
    the bias about a third of the time and the scale factor under 90 %."""
    rate = np.r_[np.linspace(-20.0, 20.0, 5), np.linspace(20.0, -20.0, 5)]  # steps 2, up then down
    t_mid = np.array([57.0, 96.0, 131.0, 166.0, 206.0, 236.0, 275.0, 310.0, 345.0, 384.0])
    rng = np.random.default_rng(5)
    n, bias_dph = 400, 3600 * 3e-4 / -0.277
    hits = np.zeros((2, 2))
    for _ in range(n):
        walk = np.cumsum(rng.normal(0.0, 1e-6, 10) * np.sqrt(np.diff(np.r_[0.0, t_mid])))
        y = -0.277 * rate + 3e-4 + walk + rng.normal(0.0, 3e-6, 10)
        for k, fit in enumerate((fit_scale_factor(rate, y, t_mid_s=t_mid), fit_scale_factor(rate, y))):
            hits[k] += (fit.scale_factor_ci95[0] <= -0.277 <= fit.scale_factor_ci95[1],
                        fit.bias_dph_ci95[0] <= bias_dph <= fit.bias_dph_ci95[1])
    cover = hits / n
    assert 0.92 <= cover[0, 0] <= 0.995 and 0.92 <= cover[0, 1] <= 0.995, cover
    assert cover[1, 0] < 0.9 and cover[1, 1] < 0.5, cover
