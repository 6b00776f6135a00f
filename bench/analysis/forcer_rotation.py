"""The forcers' rotation against the pickoffs from amplitude steps (docs/readout_phase.md section 5).

The AGC's force over the amplitude, F_a / a = gamma + 2 (da/dt) / a, applied through forcers turned
by delta_c against the pickoffs that read the wave, turns the wave at (delta_c / 2) F_a / a.  At a
steady amplitude that is gamma delta_c / 2 whatever the amplitude (a constant bias no cycle sees);
while the amplitude moves it adds delta_c d(ln a)/dt, so a step of the setpoint from a1 to a2 turns
the wave by delta_c ln(a2 / a1).  Reading that turn at four wave angles 22.5 deg apart takes out the
shares that follow the wave's angle (the skew's 4 theta, the capacitive nonlinearity's 8 theta).
Pure analysis: arrays in, results out."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: wave angles the steps are read at, from the first (deg): the mean over them cancels 4 and 8 theta patterns
ANGLES_DEG = (0.0, 22.5, 45.0, 67.5)


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
    """delta_c (rad) and its standard error: the mean of the readings' turns (taken at ANGLES_DEG)."""
    turns = np.array([r.turn_rad for r in readings])
    se = np.array([r.se_rad for r in readings])
    return float(np.mean(turns)), float(math.sqrt(np.sum(se**2)) / len(se))


def bias_drift_rad_s(amp_force_per_s: float | np.ndarray, rotation_rad: float) -> float | np.ndarray:
    """The wave's drift the rotated forcers cause under the AGC's force over the amplitude (1/s):
    (delta_c / 2) F_a / a, gamma delta_c / 2 at a steady amplitude."""
    return 0.5 * rotation_rad * amp_force_per_s
