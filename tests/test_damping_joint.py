"""The four-channel (joint) damping fit against the simulator's truth and the four-channel bound."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bench.analysis.damping import DampingFitError
from bench.analysis.damping_design import DecayScenario, four_channel_bound
from bench.analysis.damping_joint import JOINT_NAMES, fit_joint_decay
from bench.analysis.slow_model import state_from_elements
from simulators.physics.averaged import Resonator
from simulators.physics.params import preset

HRG = preset("hrg")


def test_joint_fit_reaches_the_four_channel_bound_and_finds_the_split():
    """100 deg/s, 120 s at 200 Hz: the fit's own std equals the four-channel bound (within 5 %:
    same Fisher information at the truth), every estimate is within 4 sigma of the truth,
    including the frequency split (h_c, h_s) that the energy fits cannot see."""
    rate, dur, fs = 100.0, 120.0, 200.0
    res = Resonator(HRG, seed=2)
    res.set_state(state_from_elements(1.0, 0.0, 0.3, 0.0))
    n = int(dur * fs)
    q = res.measure(res.step_block(n, 1.0 / fs, rate_rad_s=math.radians(rate)))
    t = np.arange(1, n + 1) / fs
    fit = fit_joint_decay(t, *q.T, bin_samples=4)
    bound = four_channel_bound(DecayScenario(
        tau_s=HRG.tau_s, delta_inv_tau_per_s=HRG.delta_inv_tau_per_s, noise_sigma=HRG.noise_sigma, rate_dps=rate,
        duration_s=dur, stream_hz=fs, theta_tau_deg=HRG.theta_tau_deg, theta0_deg=math.degrees(0.3),
        split_hz=HRG.split_hz, theta_w_deg=HRG.theta_w_deg))
    assert fit.converged
    assert fit.std["delta_inv_tau_per_s"] == pytest.approx(bound.std_delta_inv_tau_per_s, rel=0.05)
    truth = HRG.truth()
    for name in ("theta_tau_deg", "delta_inv_tau_per_s", "tau_s"):
        assert abs(getattr(fit, name) - truth[name]) < 4 * fit.std[name], name
    c = HRG.coefficients()
    for name, value in (("h_c", c.h_c), ("h_s", c.h_s), ("nu", 4 * c.bryan_factor * math.radians(rate))):
        i = JOINT_NAMES.index(name)
        assert abs(fit.params[i] - value) < 4 * math.sqrt(fit.covariance[i, i]), name
    assert fit.noise_sigma == pytest.approx(HRG.noise_sigma, rel=0.05)


def test_joint_fit_refuses_irregular_or_short_data():
    t = np.arange(1000) * 0.01
    t[500:] += 0.005
    z = np.ones(1000)
    with pytest.raises(DampingFitError, match="uniformly sampled"):
        fit_joint_decay(t, z, z, z, z)
    with pytest.raises(DampingFitError, match="bin_samples=0"):
        fit_joint_decay(np.arange(1000.0), z, z, z, z, bin_samples=0)
