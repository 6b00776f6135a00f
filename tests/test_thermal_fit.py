"""The thermal polynomial fit on known truth: BIC picks the true order, the intervals hold the
true coefficients, and the batch mean's standard error."""

from __future__ import annotations

import numpy as np
import pytest

from bench.analysis.thermal_fit import batch_mean, fit_temperature_polynomial


def test_bic_picks_the_true_order_and_the_intervals_hold_the_truth():
    rng = np.random.default_rng(7)
    t = np.linspace(-40.0, 85.0, 10)
    true = np.array([1.5, 0.02, 4e-4])  # about 25 degC
    sigma = np.full(t.shape, 0.01)
    orders, hits = [], []
    for _ in range(200):
        y = np.polynomial.polynomial.polyval(t - 25.0, true) + rng.normal(0.0, 0.01, t.shape)
        fit = fit_temperature_polynomial(t, y, sigma, max_order=4)
        orders.append(fit.order)
        hits += [bool(lo <= true[k] <= hi) for k, (lo, hi) in enumerate(fit.ci95[:3])]
    orders = np.array(orders)
    assert orders.min() >= 2  # the curvature is never missed
    # BIC's ln(10) = 2.3 per term: a spurious term passes when chi2_1 > 2.3 (13 %) per order tried
    assert np.mean(orders == 2) > 0.7, np.bincount(orders)
    assert 0.9 < np.mean(hits) <= 1.0  # each true coefficient inside its 95 % interval


def test_a_straight_line_is_a_straight_line():
    t = np.array([15.0, 25.0, 35.0])
    y = 5500.0 + 0.3 * (t - 25.0)
    fit = fit_temperature_polynomial(t, y + np.array([1e-4, -2e-4, 1e-4]), np.full(3, 1e-3))
    assert fit.order == 1 and fit.coeffs[1] == pytest.approx(0.3, abs=1e-4)
    assert fit.ci95[1][0] < 0.3 < fit.ci95[1][1]
    assert fit.slope_at(0.0) == pytest.approx(fit.coeffs[1])


def test_batch_mean_standard_error():
    rng = np.random.default_rng(1)
    v = rng.normal(3.0, 2.0, 10000)
    m, se = batch_mean(v, 20)
    assert m == pytest.approx(3.0, abs=4 * 0.02) and se == pytest.approx(0.02, rel=0.5)
    with pytest.raises(ValueError):
        batch_mean(v[:5], 10)


def test_a_steep_line_read_by_a_coarse_thermometer_stays_a_line():
    """f0 at 0.3 Hz/K, the temperature read to 0.1 degC, the frequency's own error 0.1 mHz: without
    the thermometer's error the steps look like curvature; with it, mostly order 1 and the true slope."""
    rng = np.random.default_rng(3)
    naive_lines, lines, slope_hits = 0, 0, 0
    for _ in range(100):
        t_true = np.linspace(-40.0, 85.0, 10) + rng.uniform(-0.3, 0.3, 10)
        t_read = np.round(t_true, 1)
        f = 5500.0 + 0.3 * (t_true - 25.0) + rng.normal(0.0, 1e-4, 10)
        sigma = np.full(10, 1e-4)
        naive_lines += fit_temperature_polynomial(t_read, f, sigma, max_order=3).order == 1
        fit = fit_temperature_polynomial(t_read, f, sigma, max_order=3, sigma_t_c=0.1 / np.sqrt(12.0))
        lines += fit.order == 1
        slope_hits += bool(fit.ci95[1][0] <= 0.3 <= fit.ci95[1][1])
    assert naive_lines < 50 and lines > 70 and slope_hits > 90, (naive_lines, lines, slope_hits)


def test_the_curves_standard_error_is_the_closed_form_and_covers():
    """se_at: a straight line's sqrt(var a + 2 x cov ab + x^2 var b) (closed form of weighted least squares
    with equal errors: var a = s^2 / n at the mean, var b = s^2 / Sxx); at t_ref it is coefficient 0's
    interval over 1.96, and over 400 seeded draws the curve at 40 degC lies within 1.96 se of the truth
    in ~95 % of them (binomial band 364-396)."""
    t = np.linspace(-20.0, 60.0, 9)
    s = 0.5
    fit = fit_temperature_polynomial(t, 3.0 + 0.1 * t, np.full(t.size, s), max_order=1, min_order=1, t_ref_c=25.0)
    x = t - 25.0
    sxx = np.sum((x - x.mean()) ** 2)
    for temp in (-20.0, 25.0, 40.0, 85.0):
        dx = temp - 25.0 - x.mean()
        expected = s * np.sqrt(1.0 / t.size + dx**2 / sxx)
        assert fit.se_at(temp)[0] == pytest.approx(expected, rel=1e-9)
    assert 1.959964 * fit.se_at(25.0)[0] == pytest.approx(fit.ci95[0][1] - fit.coeffs[0], rel=1e-6)
    rng = np.random.default_rng(7)
    inside = 0
    for _ in range(400):
        y = 3.0 + 0.1 * t + rng.normal(0.0, s, t.size)
        f = fit_temperature_polynomial(t, y, np.full(t.size, s), max_order=1, min_order=1, t_ref_c=25.0)
        inside += abs(f(40.0) - (3.0 + 0.1 * 40.0)) <= 1.959964 * f.se_at(40.0)[0]
    assert 364 <= inside <= 396
