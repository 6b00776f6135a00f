"""The readout chains' phase delay from the loops' response to a frequency-control force
(docs/readout_phase.md).  Pure analysis: arrays in, results out.

A force along the wave's phase (the FPGA's FM_FORCE_HZ = F: 4 pi a F along d q / d chi) moves the
wave's frequency by F.  Loops that read the wave's phase p late (a readout chain delay of p at the
carrier) apply it p off: F cos p of it still moves the frequency and F sin p of it pushes the
amplitude, which the amplitude loop cancels.  So over the force's square wave m F (m = +-1) the
amplitude control amp_ctrl / a moves by -4 pi sin p per Hz of m F and the PLL's frequency by cos p:
p = -atan2(k_amp / (4 pi), k_freq).  At a wave angle theta the loops read the phase through both
chains, each weighted by its share of the wave's energy: p(theta) = p_x cos^2 2th + p_y sin^2 2th
(first order), so two angles (0 and 45 deg) give both chains.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .selfcal import FM_SETTLE_S, fm_square

FOUR_PI = 4.0 * math.pi


@dataclass(frozen=True)
class PhaseReading:
    """One hold of the wave under the frequency-control force: the loops' phase error there."""

    theta_deg: float  # mean measured wave angle over the hold
    phase_deg: float  # the phase the loops read late, p(theta)
    se_deg: float  # its standard error (the half-period means' scatter)
    amp_slope_per_s_hz: float  # d(amp_ctrl / a) / d(m F): -4 pi sin p on a chain of unit gain
    freq_slope: float  # d f_pll / d(m F): cos p (times the loop gain 1 + s_m)
    halves: int  # half periods used


def _half_means(t_s: np.ndarray, fm_rate_hz: float, settle_s: float, *ys: np.ndarray) -> list[np.ndarray]:
    """Means over each half period of the square wave, its switching transient (settle_s) left out."""
    half = 0.5 / fm_rate_hz
    since = np.mod(t_s, half)
    keep = (since >= settle_s) & (since < half - 1e-9)
    idx = np.floor(t_s / half).astype(np.int64)
    idx = idx[keep] - idx[keep].min()
    n = np.bincount(idx)
    ok = n > 0
    return [np.bincount(idx, weights=np.asarray(y, dtype=float)[keep])[ok] / n[ok] for y in (t_s, *ys)]


def read_phase(t_s: np.ndarray, theta_rad: np.ndarray, amp_ctrl_rel: np.ndarray, freq_ctrl_hz: np.ndarray, *,
               fm_force_hz: float, fm_rate_hz: float, settle_s: float = FM_SETTLE_S) -> PhaseReading:
    """The loops' phase error from a hold under the frequency-control force: the half-period means of
    amp_ctrl / a and of the PLL's frequency, each regressed on (1, t, m F) (the line takes a slow
    drift of the wave's angle out), then p = -atan2(k_amp / 4 pi, k_freq), its standard error by
    the delta method from the two regressions (independent: different loops' outputs)."""
    t = np.asarray(t_s, dtype=float)
    if fm_force_hz <= 0 or fm_rate_hz <= 0:
        raise ValueError(f"fm_force_hz={fm_force_hz:g}, fm_rate_hz={fm_rate_hz:g}: the reading needs the force on")
    m = fm_square(t, fm_rate_hz) * fm_force_hz
    tb, mb, ab, fb, thb = _half_means(t, fm_rate_hz, settle_s, m, amp_ctrl_rel, freq_ctrl_hz, theta_rad)
    if len(tb) < 5:
        raise ValueError(f"{len(tb)} half periods of the frequency-control force: the reading needs at least 5")
    x = np.column_stack([np.ones_like(tb), tb - tb.mean(), mb])
    xtx_inv = np.linalg.inv(x.T @ x)
    dof = len(tb) - 3
    slopes, variances = [], []
    for y in (ab, fb):
        coef = xtx_inv @ x.T @ y
        s2 = float(np.sum((y - x @ coef) ** 2) / dof)
        slopes.append(float(coef[2]))
        variances.append(s2 * float(xtx_inv[2, 2]))
    ka, kf = slopes
    u = ka / FOUR_PI
    den = u * u + kf * kf
    phase = -math.atan2(u, kf)
    var = (kf / den) ** 2 * variances[0] / FOUR_PI**2 + (u / den) ** 2 * variances[1]
    theta_mean = 0.25 * math.atan2(float(np.mean(np.sin(4 * thb))), float(np.mean(np.cos(4 * thb))))
    return PhaseReading(math.degrees(theta_mean), math.degrees(phase), math.degrees(math.sqrt(var)), ka, kf, len(tb))


def channel_phases(readings: list[PhaseReading], floor_deg: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """(p_x, p_y) in deg and their covariance from readings at two or more wave angles: weighted
    least squares of p(theta) = p_x cos^2 2th + p_y sin^2 2th, each reading's weight 1 / (se^2 +
    floor^2).  ValueError when the angles do not separate the chains (all near one of 0, 45 deg
    modulo 90 and not the other)."""
    if len(readings) < 2:
        raise ValueError(f"{len(readings)} phase readings: the two chains need readings at two wave angles")
    th = np.radians([r.theta_deg for r in readings])
    a = np.column_stack([np.cos(2 * th) ** 2, np.sin(2 * th) ** 2])
    w = 1.0 / np.array([r.se_deg**2 + floor_deg**2 for r in readings])
    y = np.array([r.phase_deg for r in readings])
    normal = a.T @ (a * w[:, None])
    if np.linalg.cond(normal) > 1e6:
        raise ValueError("the readings' wave angles do not separate the x and y chains (take them 45 deg apart)")
    cov = np.linalg.inv(normal)
    return cov @ (a.T @ (w * y)), cov
