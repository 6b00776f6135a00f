"""Whole-angle loops that add no drift of their own (issue 19): the simulated FPGA's loops on the
World directly (no link: the loops' arithmetic is the subject), the wave's true angle recorded at
every loop block, its drift against the angle fitted with a mean and the 4, 8, 12 theta harmonics
(the same block slopes and fit as `hrg-damping`'s verification), output-referred (/K)."""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import math

import numpy as np
import pytest

from bench.analysis.damping import fit_drift_harmonics
from bench.analysis.slow_model import orbit_elements, state_from_elements
from drivers.fpga import protocol as p
from procedures.hrg_damping import block_drift
from simulators.fpga.firmware import FpgaFirmware
from simulators.physics.params import preset
from simulators.probes import EndStateProbe
from simulators.world import World


def _whole_angle(params, rate_dps: float, settle_s: float, record_s: float, compensate: bool = False):
    """Whole-angle mode at rate_dps with AGC, PLL and quadrature loop (and the damping drift's
    compensation with the true D, theta_tau); returns (t_s, theta_rad unwrapped) of the true wave
    over record_s after settle_s."""
    world = World(params, seed=1)
    world.resonator.set_state(state_from_elements(1.0, 0.0, 0.0))
    fw = FpgaFirmware(world)
    world.attach(fw)
    for name, value in (("REF_FREQ_HZ", params.f0_hz), ("AGC_SETPOINT", 1.0), ("PRECESSION_RATE_DPS", rate_dps),
                        ("DRIFT_D_PER_S", params.delta_inv_tau_per_s), ("DRIFT_THETA_TAU_DEG", params.theta_tau_deg)):
        fw.write(p.BY_NAME[name], value)
    comp = p.DRIFT_COMP_EN if compensate else 0
    fw.write(p.BY_NAME["CTRL"], p.DRIVE_EN | p.AGC_EN | p.PLL_EN | p.QUAD_EN | p.WHOLE_ANGLE | comp)
    world.advance(settle_s)
    truth = EndStateProbe()
    world.attach(truth)
    world.advance(record_s)
    theta = np.unwrap(4.0 * orbit_elements(np.array(truth.q))["theta_rad"]) / 4.0
    return np.array(truth.t_s), theta


def _drift_dph(params, t_s, theta, rate_dps):
    mids, rate = block_drift(t_s, theta, 0.5)
    to_dph = math.degrees(1.0 / params.bryan_factor) * 3600
    return fit_drift_harmonics(mids, rate - math.radians(rate_dps), orders=(4, 8, 12, 16)).scaled(to_dph)


@pytest.mark.parametrize("rate_dps", [2.0, -10.0])
def test_ideal_resonator_precesses_at_the_command_with_no_drift(rate_dps):
    """No damping anisotropy, no split, no noise: over a whole turn of the wave pattern (180 deg of
    theta) the wave turns at the command within 1e-4 relative and the drift's mean and every
    harmonic are under 0.1 deg/h output-referred.  (Forces held over a 50 ms block along the
    wave's angle of the block before gave -4.2 deg/h at 2 deg/s, 1.6e-4 of the rate.)"""
    params = preset("hrg-ideal")
    record_s = 180.0 / abs(rate_dps)
    t_s, theta = _whole_angle(params, rate_dps, 15.0, record_s)
    rate = math.degrees(np.polyfit(t_s, theta, 1)[0])
    assert abs(rate / rate_dps - 1.0) < 1e-4, rate
    fit = _drift_dph(params, t_s, theta, rate_dps)
    assert abs(fit.mean) < 0.1, fit
    for m, h in fit.harmonics.items():
        assert h.amplitude < 0.1, (m, h)


def test_split_adds_no_drift_once_learnt():
    """A 5 mHz split (no damping anisotropy, no noise) at 2 deg/s: once the quadrature loop has
    learnt the split (30 s), the mean and the 8 theta drift are under 0.3 deg/h output-referred
    (a wave-frame PI left 25 deg/h of each: the split turns its lagging quadrature into drift)."""
    params = preset("hrg", delta_inv_tau_per_s=0.0, noise_sigma=0.0)
    t_s, theta = _whole_angle(params, 2.0, 30.0, 90.0)
    fit = _drift_dph(params, t_s, theta, 2.0)
    assert abs(fit.mean) < 0.3, fit
    for m, h in fit.harmonics.items():
        assert h.amplitude < 0.3, (m, h)


@pytest.mark.parametrize("rate_dps", [10.0, -10.0])
def test_compensated_drift_at_10_dps_is_under_0_1_dph_per_harmonic(rate_dps):
    """The `hrg` resonator (D 1.6e-4 1/s: (D/4)/K = 29.8 deg/h; split 5 mHz), no noise, 10 deg/s of
    commanded precession over two turns of the 4 theta pattern: uncompensated the 4 theta drift is
    (D/4)/K times the 0.5 s slope window's 1 - x^2/10 (x = 4 x 10 deg/s x 0.25 s) within 0.05 deg/h;
    compensated with the true (D, theta_tau) the mean and every harmonic are under 0.1 deg/h (issue 33
    item 4).  Before the precession force took the amplitude predicted at the block's middle, the
    AGC's lag behind the damping's 4 theta amplitude pattern made F_p / (4 a) miss the command by
    that lag: the drift read 1.5 % low uncompensated and 0.37 deg/h of 4 theta was left."""
    params = preset("hrg", noise_sigma=0.0)
    record_s = 180.0 / abs(rate_dps)
    x = 4.0 * math.radians(abs(rate_dps)) * 0.25
    want = math.degrees(params.delta_inv_tau_per_s / 4.0 / params.bryan_factor) * 3600.0 * (1.0 - x * x / 10.0)
    fit = _drift_dph(params, *_whole_angle(params, rate_dps, 30.0, record_s), rate_dps)
    assert fit.harmonics[4].amplitude == pytest.approx(want, abs=0.05), fit
    fit = _drift_dph(params, *_whole_angle(params, rate_dps, 30.0, record_s, compensate=True), rate_dps)
    assert abs(fit.mean) < 0.1, fit
    for m, h in fit.harmonics.items():
        assert h.amplitude < 0.1, (m, h)


def test_drift_harmonics_fit_recovers_known_terms():
    """fit_drift_harmonics on a synthetic drift: mean, 4 and 8 theta terms and phases come back and
    the rest is the noise's rms; over 400 seeds the 8 theta interval holds the truth and the absent
    12 theta term's interval holds 0 at least ~95 % of the time (binomial slack: 400 draws)."""
    th = np.linspace(0, math.pi, 400, endpoint=False)
    clean = 1.5 + 3.0 * np.sin(4 * (th - 0.2)) + 0.7 * np.sin(8 * (th - 0.05))
    fit = fit_drift_harmonics(th, clean + np.random.default_rng(1).normal(0, 0.1, th.size))
    assert fit.mean == pytest.approx(1.5, abs=0.03)
    assert fit.harmonics[4].amplitude == pytest.approx(3.0, abs=0.03)
    assert fit.harmonics[4].phase_rad == pytest.approx(0.2, abs=0.01)
    assert fit.harmonics[8].amplitude == pytest.approx(0.7, abs=0.03)
    assert fit.harmonics[8].phase_rad == pytest.approx(0.05, abs=0.01)
    assert fit.rest_rms == pytest.approx(0.1, rel=0.15)
    holds_8 = holds_0 = holds_mean = 0
    for seed in range(400):
        f = fit_drift_harmonics(th, clean + np.random.default_rng(seed).normal(0, 0.1, th.size))
        holds_8 += f.harmonics[8].ci95[0] <= 0.7 <= f.harmonics[8].ci95[1]
        holds_0 += f.harmonics[12].ci95[0] == 0.0
        holds_mean += f.mean_ci95[0] <= 1.5 <= f.mean_ci95[1]
    assert holds_8 >= 372 and holds_0 >= 372 and holds_mean >= 372, (holds_8, holds_0, holds_mean)


class _TrueAngle:
    """The true wave angle at the end of every block."""

    def __init__(self) -> None:
        self.t_s: list[float] = []
        self.theta_rad: list[float] = []

    def before_block(self, *args) -> None:
        pass

    def after_block(self, world, block) -> None:
        self.t_s.append(float(block.t_s[-1]))
        self.theta_rad.append(float(orbit_elements(block.q_true[-1:])["theta_rad"][0]))


@pytest.mark.parametrize("case_rate_dps", [20.0, -36.0])
def test_split_leaves_no_scale_error_when_the_case_turns(case_rate_dps):
    """A 5 mHz split (no damping anisotropy, no noise), the case turning at 20 or 36 deg/s, no
    precession command: the wave turns at -K Omega within 3e-7 relative (0.02 deg/h output-referred
    at 20 deg/s).  It used to turn 3.1 ppm (20 deg/s) and 0.8 ppm (36 deg/s) slow: the split
    observer's ridge learnt the pumping 0.1-0.2 % low, and chi's prediction left out the split's
    frequency pattern turning with the wave (docs/fpga_link.md "Whole-angle loops")."""
    params = preset("hrg", delta_inv_tau_per_s=0.0, noise_sigma=0.0)
    world = World(params, seed=1)
    world.resonator.set_state(state_from_elements(1.0, 0.0, 0.0))
    fw = FpgaFirmware(world)
    world.attach(fw)
    for name, value in (("REF_FREQ_HZ", params.f0_hz), ("AGC_SETPOINT", 1.0)):
        fw.write(p.BY_NAME[name], value)
    fw.write(p.BY_NAME["CTRL"], p.DRIVE_EN | p.AGC_EN | p.PLL_EN | p.QUAD_EN | p.WHOLE_ANGLE)
    world.case_rate_dps = case_rate_dps
    world.advance(20.0)
    truth = _TrueAngle()
    world.attach(truth)
    world.advance(40.0)
    theta = np.unwrap(4.0 * np.array(truth.theta_rad)) / 4.0
    rate_dps = math.degrees(np.polyfit(truth.t_s, theta, 1)[0])
    want_dps = -params.bryan_factor * case_rate_dps
    assert abs(rate_dps / want_dps - 1.0) < 3e-7, (rate_dps / want_dps - 1.0) * 1e6
