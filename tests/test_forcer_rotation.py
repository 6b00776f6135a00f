"""The forcers' rotation against the pickoffs from amplitude steps (bench/analysis/forcer_rotation.py,
procedures/forcer_rotation.py; docs/readout_phase.md section 5) against known truth."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bench.analysis import forcer_rotation as fr

HOLD_S = 30.0


def _record(rotation_rad: float, seed: int, walk_rad_rts: float, steps: int = 40, ratio: float = 2.0):
    """A wave at rest drifting at a constant rate plus rotation x ln a(t) (the setpoint stepped between
    ratio and 1 every HOLD_S, the AGC settling with a 2 s time constant) plus a random walk of the angle."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, steps * HOLD_S, 1.0)
    target = np.where(np.floor(t / HOLD_S) % 2 == 0, math.log(ratio), 0.0)
    ln_a = np.zeros_like(t)
    for i in range(1, len(t)):
        ln_a[i] = ln_a[i - 1] + (target[i] - ln_a[i - 1]) * (1.0 - math.exp(-0.5))
    theta = 0.3 + 2e-6 * t + rotation_rad * ln_a + np.cumsum(walk_rad_rts * rng.standard_normal(len(t)))
    return t, theta, ln_a


def test_the_turn_per_ln_amplitude_is_the_rotation_noise_free():
    t, th, ln_a = _record(math.radians(0.04), 0, 0.0)
    r = fr.read_turn(t, th, ln_a, HOLD_S)
    assert r.turn_rad == pytest.approx(math.radians(0.04), rel=1e-6)


def test_its_interval_covers_the_truth_under_an_angle_random_walk():
    """Seeded: the 95 % interval (+-1.96 se) of 200 records covers the truth 0.91-0.99 of the time."""
    truth = math.radians(0.04)
    hits = 0
    for seed in range(200):
        r = fr.read_turn(*_record(truth, 100 + seed, 3e-5), HOLD_S)
        hits += abs(r.turn_rad - truth) <= 1.96 * r.se_rad
    assert 0.91 <= hits / 200 <= 0.99, hits


def test_the_4_and_8_theta_shares_are_fitted_out_at_the_angles_read():
    """The skew's share (cos 4 theta) and the nonlinearity's (sin 8 theta) drop out of the constant
    fitted beside them, at angles ANGLES_DEG apart from a first one anywhere and each moved by the
    wave's drift while read (a plain mean would keep 1e-4 of the 2e-3 share here); 4 readings are refused."""
    rot = 7e-4
    readings = []
    for i, ang in enumerate(fr.ANGLES_DEG):
        th = math.radians(ang + 13.0 + 1.7 * i)
        readings.append(fr.StepReading(math.degrees(th), rot + 2e-3 * math.cos(4 * th) - 5e-4 * math.sin(8 * th),
                                       1e-5, 10))
    value, se = fr.rotation_from_readings(readings)
    assert value == pytest.approx(rot, rel=1e-9)
    assert 0 < se < 1e-5
    assert abs(np.mean([r.turn_rad for r in readings]) - rot) > 5e-5
    with pytest.raises(ValueError, match="4 readings"):
        fr.rotation_from_readings(readings[:4])


def test_too_few_holds_are_refused():
    t, th, ln_a = _record(1e-3, 0, 0.0, steps=3)
    with pytest.raises(ValueError, match="3 holds: the amplitude steps need at least 4"):
        fr.read_turn(t, th, ln_a, HOLD_S)


def test_selfcal_reads_the_rotation_and_takes_its_constant_bias_out(monkeypatch):
    """hrg-realistic's electrode angles alone (pickoff 0.05 / -0.08, forcer 0.1 / -0.05 deg: the forcers
    0.04 deg turned against the pickoffs), noise-free, 2 cycles at 0.25 deg/s: the mean bias is -1.70
    deg/h with the cycles alone (gamma delta_c / (2 K)); the rotation read from 4 steps at each of 8 angles
    is 0.04 deg to 1 % (0.04006 read with 30 s holds), and the rate with its drift removed has a mean
    under 0.06 deg/h (+0.011)."""
    from simulators.physics.errors import ErrorSources
    from tests.test_selfcal_gains import _selfcal_on

    angles = ErrorSources(pickoff_angle_x_deg=0.05, pickoff_angle_y_deg=-0.08, forcer_angle_x_deg=0.1,
                          forcer_angle_y_deg=-0.05)
    m = _selfcal_on(angles, monkeypatch, {"rotation_cal": 4})
    assert m["forcer_rotation_deg"] == pytest.approx(0.04, rel=0.01), m
    assert abs(m["mean_bias_dph"]) < 0.06, m
