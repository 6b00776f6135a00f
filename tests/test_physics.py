"""Resonator physics against closed forms (PHYSICS.md sections 1-2)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bench.analysis.slow_model import invariants, orbit_elements, slow_rhs, state_from_elements
from simulators.physics.averaged import Resonator
from simulators.physics.carrier import integrate_carrier, iq_demodulate
from simulators.physics.params import ParameterError, ResonatorParams, preset


def wave(a: float = 1.0, k: float = 0.0, theta_deg: float = 0.0, chi: float = 0.0) -> np.ndarray:
    return state_from_elements(a, k, math.radians(theta_deg), chi)


def test_isotropic_free_decay_follows_exp_minus_2t_over_tau():
    p = ResonatorParams(f0_hz=5500.0, tau_s=300.0)
    r = Resonator(p)
    r.set_state(wave(1.0, 0.0, 12.0))
    q = r.step_block(3000, 0.1)  # 300 s at 10 Hz
    t = 0.1 * np.arange(1, 3001)
    e = orbit_elements(q)["E"]
    # exact matrix exponential: agreement to rounding
    np.testing.assert_allclose(e, np.exp(-2.0 * t / 300.0), rtol=1e-10)


def test_wave_precesses_at_minus_k_omega_relative_to_case():
    p = ResonatorParams(f0_hz=5500.0, tau_s=300.0, bryan_factor=0.277)
    r = Resonator(p)
    r.set_state(wave(1.0, 0.0, 0.0))
    rate = math.radians(10.0)  # 10 deg/s keeps the wave inside (-45, 45] deg for 10 s
    q = r.step_block(1000, 0.01, rate_rad_s=rate)
    theta = np.unwrap(4 * orbit_elements(q)["theta_rad"]) / 4
    t = 0.01 * np.arange(1, 1001)
    np.testing.assert_allclose(theta, -0.277 * rate * t, atol=1e-12)


@pytest.mark.parametrize("theta_deg", [0.0, 10.0, 30.0, 55.0, 80.0])
def test_damping_drift_at_held_angle_is_d_over_4_sin_4_theta(theta_deg):
    d, th_tau = 2e-3, 25.0
    p = ResonatorParams(f0_hz=5500.0, tau_s=300.0, delta_inv_tau_per_s=d, theta_tau_deg=th_tau)
    q0 = wave(1.0, 0.0, theta_deg)
    dq = slow_rhs(q0, p.coefficients().zg(0.0))
    # d theta / dt from the invariants: theta = atan2(S, R)/4
    h = 1e-6
    th = [orbit_elements(q0 + s * h * dq)["theta_rad"] for s in (-1, 1)]
    rate = math.remainder(th[1] - th[0], math.pi / 2) / (2 * h)
    expected = d / 4 * math.sin(4 * math.radians(theta_deg - th_tau))
    assert rate == pytest.approx(expected, rel=1e-6, abs=1e-12)
    # and the same through the integrator over a short interval
    r = Resonator(p)
    r.set_state(q0)
    q = r.step_block(1, 0.1)
    turned = math.remainder(orbit_elements(q[-1])["theta_rad"] - math.radians(theta_deg), math.pi / 2)
    integrated = turned / 0.1
    assert integrated == pytest.approx(expected, rel=1e-3, abs=1e-9)


@pytest.mark.parametrize("theta_deg", [5.0, 20.0, 40.0])
def test_quadrature_grows_from_a_split(theta_deg):
    split_hz, th_w = 0.01, 10.0
    p = ResonatorParams(f0_hz=5500.0, tau_s=1e6, split_hz=split_hz, theta_w_deg=th_w)
    r = Resonator(p)
    r.set_state(wave(1.0, 0.0, theta_deg))
    dt = 0.01
    q = r.step_block(1, dt)
    k = orbit_elements(q[-1])["k"]
    dw = 2 * math.pi * split_hz
    expected = 0.5 * dw * math.sin(4 * math.radians(theta_deg - th_w)) * dt  # dk/dt = (a Dw/2) sin 4(th - th_w)
    assert k == pytest.approx(expected, rel=2e-3)


def test_forced_steady_state_at_resonance_peak():
    # isotropic, offset c_m/2: the amplitude peaks at drive = f0 + offset, with |q| = |u| / gamma
    offset_hz = 0.5
    p = ResonatorParams(f0_hz=1000.0, tau_s=0.2, freq_offset_hz=offset_hz)
    r = Resonator(p)
    u = np.array([0.0, 3.0, 0.0, 0.0])
    freqs = 1000.0 + np.linspace(-3, 4, 141)
    amps = [np.linalg.norm(r.steady_state(force=u, ref_freq_hz=f)) for f in freqs]
    f_peak = freqs[int(np.argmax(amps))]
    assert f_peak == pytest.approx(1000.0 + offset_hz, abs=0.05)
    gamma = 2 / 0.2
    assert max(amps) == pytest.approx(3.0 / gamma, rel=1e-3)
    # the integrator settles to the same state after ~20 tau
    r.set_state(np.zeros(4))
    q = r.step_block(400, 0.01, force=u, ref_freq_hz=1000.0 + offset_hz)
    np.testing.assert_allclose(q[-1], r.steady_state(force=u, ref_freq_hz=1000.0 + offset_hz), atol=1e-9)


def test_cubic_nonlinearity_shifts_phase_with_amplitude_and_keeps_energy():
    # k_cubic only rotates the phase: d chi/dt = -(3/8) xi E for a single-axis wave (g = 0)
    xi = 2.0
    p = ResonatorParams(f0_hz=1000.0, tau_s=1e9, xi_per_s=xi)
    r = Resonator(p)
    q0 = wave(1.0, 0.0, 0.0)
    r.set_state(q0)
    q = r.step_block(100, 0.01)
    e = orbit_elements(q)["E"]
    np.testing.assert_allclose(e, 1.0, rtol=1e-8)
    phase = np.unwrap(np.arctan2(-q[:, 1], q[:, 0]))  # chi from cx = a cos chi, sx = -a sin chi
    t = 0.01 * np.arange(1, 101)
    np.testing.assert_allclose(phase, -(3 / 8) * xi * t, atol=1e-6)


def test_invariants_match_orbit_elements():
    rng = np.random.default_rng(3)
    for _ in range(20):
        a, k = rng.uniform(0.5, 2.0), rng.uniform(-0.4, 0.4)
        th, chi = rng.uniform(-0.7, 0.7), rng.uniform(-3, 3)
        q = state_from_elements(a, k, th, chi)
        inv = invariants(q)
        assert inv["E"] == pytest.approx(a * a + k * k)
        assert inv["R"] == pytest.approx((a * a - k * k) * math.cos(4 * th))
        assert inv["S"] == pytest.approx((a * a - k * k) * math.sin(4 * th))
        assert inv["Q"] == pytest.approx(2 * a * k)
        el = orbit_elements(q)
        assert el["a"] == pytest.approx(a)
        assert el["k"] == pytest.approx(k)
        assert math.remainder(el["theta_rad"] - th, math.pi / 2) == pytest.approx(0.0, abs=1e-9)


def test_carrier_level_agrees_with_averaged_model():
    """Every term at once, demodulated in software.  Averaging is first order in eps/w: with the
    largest coefficient ~2 1/s against w = 2 pi 50 Hz the difference is a few 1e-3 of the
    amplitude, so the tolerance is 5e-3 of the initial amplitude."""
    p = ResonatorParams(
        f0_hz=50.0, tau_s=1.0, delta_inv_tau_per_s=0.3, theta_tau_deg=10, split_hz=0.2, theta_w_deg=30,
        freq_offset_hz=0.1, circulatory_per_s=0.05, xi_per_s=0.5, kappa_per_s=0.2,
    )
    q0 = state_from_elements(1.0, 0.1, 0.2, 0.3)
    u = np.array([0.1, 0.2, -0.1, 0.05])
    fs = 5000.0
    t, x, y = integrate_carrier(p, q0, 1.6, fs_hz=fs, rate_rad_s=0.5, force=u, ref_freq_hz=50.0)
    tc, cx, sx = iq_demodulate(t, x, 50.0, fs)
    _, cy, sy = iq_demodulate(t, y, 50.0, fs)
    r = Resonator(p)
    r.set_state(q0)
    q = r.step_block(8000, 1 / fs, rate_rad_s=0.5, force=u, ref_freq_hz=50.0)
    ta = np.arange(1, 8001) / fs
    for t_check in (0.5, 1.0, 1.5):
        demod = [np.interp(t_check, tc, s) for s in (cx, sx, cy, sy)]
        avg = [np.interp(t_check, ta, q[:, i]) for i in range(4)]
        np.testing.assert_allclose(demod, avg, atol=5e-3)


def test_parameter_errors_are_clear():
    with pytest.raises(ParameterError, match="q_factor=-5"):
        ResonatorParams.from_q(5500.0, -5.0)
    with pytest.raises(ParameterError, match="tau_s=nan"):
        ResonatorParams(f0_hz=5500.0, tau_s=float("nan"))
    with pytest.raises(ParameterError, match="unknown resonator preset 'quartz'"):
        preset("quartz")
    with pytest.raises(ParameterError, match="delta_inv_tau_per_s"):
        ResonatorParams(f0_hz=10.0, tau_s=1.0, delta_inv_tau_per_s=3.0)
    with pytest.raises(ParameterError, match="unknown resonator parameter"):
        preset("hrg", tau=3.0)


def test_mems_preset_is_maslovs_identified_model():
    c = preset("mems").coefficients()
    assert c.w0_rad_s == pytest.approx(85732.0)
    for name, value in dict(gamma=43.029, b_c=1.332, b_s=-1.389, c_m=24.358, n=1.173, h_c=-12.797,
                            h_s=11.588, xi=18.217, nu_offset=2.029).items():
        assert getattr(c, name) == pytest.approx(value, rel=1e-9), name
    assert preset("mems").q_factor == pytest.approx(1992, rel=1e-3)
    assert preset("hrg").q_factor == pytest.approx(math.pi * 5500 * 300)
