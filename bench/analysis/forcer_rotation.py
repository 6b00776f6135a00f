"""The forcers' rotation against the pickoffs from amplitude steps (docs/readout_phase.md section 5).

The AGC's force over the amplitude, F_a / a = gamma + 2 (da/dt) / a, applied through forcers turned
by delta_c against the pickoffs that read the wave, turns the wave at (delta_c / 2) F_a / a.  At a
steady amplitude that is gamma delta_c / 2 whatever the amplitude (a constant bias no cycle sees);
while the amplitude moves it adds delta_c d(ln a)/dt, so a step of the setpoint from a1 to a2 turns
the wave by delta_c ln(a2 / a1).  Reading that turn at eight wave angles over 90 deg and fitting the
shares that follow the wave's angle (the skew's 4 theta, the capacitive nonlinearity's 8 theta) beside it
leaves delta_c.
Pure analysis: arrays in, results out."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: wave angles the steps are read at, from the first (deg): 8 over 90 deg, so the 4 and 8 theta patterns the
#: turn also carries are fitted beside it (the wave drifts while it is read: the angles are not exact)
ANGLES_DEG = (0.0, 11.25, 22.5, 33.75, 45.0, 56.25, 67.5, 78.75)


@dataclass(frozen=True)
class StepReading:
    """The wave's turn per unit of ln(amplitude) at one wave angle (rad per unit), its standard
    error, and the wave angle (deg)."""

    theta_deg: float
    turn_rad: float
    se_rad: float
    steps: int


def hold_means(t_s: np.ndarray, theta_rad: np.ndarray, ln_amp: np.ndarray, hold_s: float,
               settled: float = 0.5) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Means of (t, theta, ln a) over the settled last `settled` share of each hold of hold_s
    (the holds counted from t_s[0])."""
    t = np.asarray(t_s, dtype=float)
    j = np.floor((t - t[0]) / hold_s).astype(int)
    into = (t - t[0]) - j * hold_s
    keep = into >= (1.0 - settled) * hold_s
    out = []
    for y in (t, np.asarray(theta_rad, dtype=float), np.asarray(ln_amp, dtype=float)):
        n = np.bincount(j[keep], minlength=j.max() + 1)
        s = np.bincount(j[keep], weights=y[keep], minlength=j.max() + 1)
        out.append(s[n > 0] / n[n > 0])
    return out[0], out[1], out[2]


def read_turn(t_s: np.ndarray, theta_rad: np.ndarray, ln_amp: np.ndarray, hold_s: float) -> StepReading:
    """The turn per unit ln a over a record of setpoint steps every hold_s: the changes of the hold
    means of theta regressed on (the time between them, the change of ln a); the angle's noise is a
    random walk over these lags, so the changes are close to independent and OLS's error holds."""
    tm, thm, lam = hold_means(t_s, theta_rad, ln_amp, hold_s)
    if len(tm) < 4:
        raise ValueError(f"{len(tm)} holds: the amplitude steps need at least 4")
    x = np.column_stack([np.diff(tm), np.diff(lam)])
    y = np.diff(thm)
    coef, *_ = np.linalg.lstsq(x, y, rcond=None)
    dof = len(y) - 2
    s2 = float(np.sum((y - x @ coef) ** 2) / max(1, dof))
    cov = s2 * np.linalg.inv(x.T @ x)
    return StepReading(float(math.degrees(np.mean(theta_rad))), float(coef[1]), float(math.sqrt(cov[1, 1])),
                       len(y))


def rotation_from_readings(readings: list[StepReading]) -> tuple[float, float]:
    """delta_c (rad) and its standard error: the constant of the readings' turns weighted by 1/se^2 on
    (1, cos 4th, sin 4th, cos 8th, sin 8th) at the angles they were read at (the skew's and the
    nonlinearity's shares; the wave drifts while read, so equal spacing alone does not cancel them);
    its error widened by the scatter when that is larger than the readings' errors.  Needs 5 readings
    at distinct angles (ANGLES_DEG gives 8)."""
    turns = np.array([r.turn_rad for r in readings])
    se = np.array([r.se_rad for r in readings])
    if len(turns) < 5:
        raise ValueError(f"{len(turns)} readings: the rotation's fit on the 4 and 8 theta shares needs at least 5")
    th = np.radians([r.theta_deg for r in readings])
    x = np.column_stack([np.ones_like(th), np.cos(4 * th), np.sin(4 * th), np.cos(8 * th), np.sin(8 * th)])
    w = 1.0 / se**2
    cov = np.linalg.inv(x.T @ (w[:, None] * x))
    coef = cov @ (x.T @ (w * turns))
    dof = len(turns) - x.shape[1]
    if dof > 0:
        cov = cov * max(1.0, float(np.sum(w * (turns - x @ coef) ** 2)) / dof)
    return float(coef[0]), float(math.sqrt(cov[0, 0]))


def bias_drift_rad_s(amp_force_per_s: float | np.ndarray, rotation_rad: float) -> float | np.ndarray:
    """The wave's drift the rotated forcers cause under the AGC's force over the amplitude (1/s):
    (delta_c / 2) F_a / a, gamma delta_c / 2 at a steady amplitude."""
    return 0.5 * rotation_rad * amp_force_per_s
