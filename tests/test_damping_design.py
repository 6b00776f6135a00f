"""Cramer-Rao bounds and the experiment design of the HRG damping test (damping_design)."""

from __future__ import annotations

import math

import pytest

from bench.analysis.damping_design import (
    DecayScenario,
    design_hrg_damping,
    energy_bound,
    four_channel_bound,
    model_bias,
)

# PHYSICS.md section 3's measured case: 300 s at 200 Hz, noise 1e-4, tau 300 s, D 2e-4, K 0.277
BASE = DecayScenario(tau_s=300.0, delta_inv_tau_per_s=2e-4, noise_sigma=1e-4, duration_s=300.0, stream_hz=200.0,
                     theta_tau_deg=20.0)


def test_energy_bound_matches_published_scatter_and_scales_with_rate():
    """PHYSICS 3 measured the plain fit's scatter of D at 8.5 % (500 deg/s) and 1.8 % (100 deg/s):
    the bound is 8.5 % and 1.7 %, and it falls in proportion to the rate (5x within 3 %)."""
    b500 = energy_bound(BASE)
    b100 = energy_bound(DecayScenario(**{**BASE.__dict__, "rate_dps": 100.0}))
    assert b500.std_delta_inv_tau_per_s / 2e-4 == pytest.approx(0.085, rel=0.05)
    assert b100.std_delta_inv_tau_per_s / 2e-4 == pytest.approx(0.017, rel=0.08)
    assert b500.std_delta_inv_tau_per_s / b100.std_delta_inv_tau_per_s == pytest.approx(5.0, rel=0.03)


def test_four_channel_bound_is_tighter_by_about_1_4():
    """PHYSICS 3 (d): all four channels carry 1.4-1.5x less std than E alone."""
    ratio = energy_bound(BASE).std_delta_inv_tau_per_s / four_channel_bound(BASE).std_delta_inv_tau_per_s
    assert 1.3 < ratio < 1.6


def test_patent_model_bias_grows_at_low_rate():
    """A 0.05 rad/s split and 0.02 quadrature: the cos 4 theta model is unbiased to 0.1 % at
    100 deg/s but several % low at 5 deg/s; the exact model stays under 0.3 %."""
    sc = DecayScenario(**{**BASE.__dict__, "split_hz": 0.05 / (2 * math.pi), "quadrature": 0.02})
    fast = model_bias(DecayScenario(**{**sc.__dict__, "rate_dps": 100.0}))
    slow = model_bias(DecayScenario(**{**sc.__dict__, "rate_dps": 5.0}))
    exact = model_bias(DecayScenario(**{**sc.__dict__, "rate_dps": 5.0}), model="exact")
    assert abs(fast[0]) / 2e-4 < 1e-3
    assert slow[0] / 2e-4 < -0.03
    assert abs(exact[0]) / 2e-4 < 3e-3


def test_design_recommends_a_slower_table_and_prints_it():
    """For the HRG preset with a trimmed split, a rate well below 500 deg/s wins by a large factor
    (the scatter falls with the rate until the split bias or collinearity stops it)."""
    d = design_hrg_damping(tau_s=300.0, delta_inv_tau_per_s=1.6e-4, noise_sigma=1e-4, split_hz=0.005,
                           quadrature=0.02, theta_tau_deg=20.0, rates_dps=(2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 500.0),
                           lengths_tau=(1.0, 3.0))
    assert d.recommended.rate_dps < 500.0
    assert d.gain_vs_patent > 5.0
    text = d.summary()
    assert "recommended: table rate" in text and "four-channel bound" in text
    assert d.four_channel_recommended.std_delta_inv_tau_per_s < d.recommended.std_delta_inv_tau_per_s


def test_patent_model_is_pushed_to_faster_rates_by_its_bias():
    """With a 0.05 rad/s split and 0.02 quadrature the cos 4 theta model's bias grows as the rate
    falls, so its best rate is faster than the quadrature-aware model's, and its error larger."""
    kw = dict(tau_s=300.0, delta_inv_tau_per_s=2e-4, noise_sigma=1e-4, stream_hz=200.0,
              split_hz=0.05 / (2 * math.pi), quadrature=0.02, theta_tau_deg=20.0,
              rates_dps=(2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 500.0), lengths_tau=(1.0,))
    patent = design_hrg_damping(model="patent", **kw)
    exact = design_hrg_damping(model="exact", **kw)
    assert patent.recommended.rate_dps > exact.recommended.rate_dps
    assert patent.recommended.total_rel > exact.recommended.total_rel


def test_design_rejects_bad_input():
    with pytest.raises(ValueError, match="delta_inv_tau_per_s=0"):
        design_hrg_damping(tau_s=300.0, delta_inv_tau_per_s=0.0, noise_sigma=1e-4)
    with pytest.raises(ValueError, match="locking rate"):
        design_hrg_damping(tau_s=300.0, delta_inv_tau_per_s=1.6e-4, noise_sigma=1e-4, rates_dps=(0.001, 1.0))
    with pytest.raises(ValueError, match="noise_sigma=-1"):
        DecayScenario(tau_s=300.0, delta_inv_tau_per_s=1e-4, noise_sigma=-1.0)
