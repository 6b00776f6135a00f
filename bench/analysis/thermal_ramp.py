"""The ramp method's analysis (docs/chamber.md, "The ramp method"): segment statistics of a
quantity that moves during its record, the thermometers a ramp offers (the chamber air, the part
thermocouple on the case, the resonator's own frequency) and the heating-cooling gap that shows a
thermometer's lag behind what the resonator feels.  Pure: arrays in, results out."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .thermal_fit import LEVEL, ThermalFit, birge_half_widths, fit_temperature_polynomial


def _stats():
    """scipy.stats, imported on first use: a process that only loads the procedures (the line's
    limits, `gyrobench list`) never pays its ~0.4 s (issue 36)."""
    from scipy import stats

    return stats


def trend_mean(values, n_batches: int = 10) -> tuple[float, float]:
    """Mean of a record that drifts (a ramp) and its standard error from the scatter of its batch
    means about a straight line (ddof 2), so the drift itself is not taken for noise."""
    v = np.asarray(values, dtype=float)
    if n_batches < 3 or len(v) < 2 * n_batches:
        raise ValueError(f"{len(v)} samples for {n_batches} batches: need 3 batches or more, 2 samples a batch")
    means = np.array([b.mean() for b in np.array_split(v, n_batches)])
    k = np.arange(n_batches, dtype=float)
    resid = means - np.polyval(np.polyfit(k, means, 1), k)
    return float(v.mean()), float(math.sqrt(np.sum(resid**2) / (n_batches - 2) / n_batches))


def frequency_thermometer(f_hz, f_se_hz, part_c, *, t_ref_c: float = 25.0, sigma_t_c: float = 0.0
                          ) -> tuple[np.ndarray, np.ndarray, ThermalFit]:
    """The resonator frequency read as a temperature: a straight line f(T) fitted on the part
    thermocouple over both branches (the lags cancel to first order, Niu et al. 2013), inverted;
    (temperatures, their standard errors, the line)."""
    line = fit_temperature_polynomial(part_c, f_hz, f_se_hz, max_order=1, min_order=1, t_ref_c=t_ref_c,
                                      sigma_t_c=sigma_t_c)
    f = np.asarray(f_hz, dtype=float)
    slope = float(line.coeffs[1])
    return t_ref_c + (f - line.coeffs[0]) / slope, np.asarray(f_se_hz, dtype=float) / abs(slope), line


@dataclass(frozen=True)
class BranchGap:
    """Mean fit residual on heating minus that on cooling, and the thermometer's lag it means."""

    gap: float
    gap_ci95: tuple[float, float]
    lag_c: float
    lag_ci95_c: tuple[float, float]


def branch_gap(fit: ThermalFit, heating, slope: float) -> BranchGap:
    """The heating-cooling gap of a fit's residuals (Welch's interval) and the lag behind the
    quantity it means: on heating what the resonator feels trails the thermometer by lag_c, so
    y reads slope * lag_c low there and as much high on cooling: lag_c = -gap / (2 slope)."""
    h = np.asarray(heating, dtype=bool)
    up, down = fit.residuals[h], fit.residuals[~h]
    if len(up) < 2 or len(down) < 2:
        raise ValueError(f"{len(up)} heating and {len(down)} cooling points: 2 or more of each are needed")
    gap = float(up.mean() - down.mean())
    va, vb = up.var(ddof=1) / len(up), down.var(ddof=1) / len(down)
    se = math.sqrt(va + vb)
    dof = (va + vb) ** 2 / (va**2 / (len(up) - 1) + vb**2 / (len(down) - 1)) if se > 0 else 1.0
    half = float(_stats().t.ppf(0.5 + LEVEL / 2, dof)) * se
    lags = sorted((-(gap - half) / (2 * slope), -(gap + half) / (2 * slope)))
    return BranchGap(gap, (gap - half, gap + half), -gap / (2 * slope), (lags[0], lags[1]))


def record_slope(t_s, values) -> float:
    """The straight-line slope of a record against time (units of values per s): a segment's
    frequency rate on a ramp, which a drive loop trails by a phase proportional to it."""
    t = np.asarray(t_s, dtype=float)
    v = np.asarray(values, dtype=float)
    if len(t) < 2 or np.ptp(t) <= 0:
        raise ValueError(f"{len(t)} samples: a slope needs 2 or more at distinct times")
    return float(np.polyfit(t - t.mean(), v, 1)[0])


@dataclass(frozen=True)
class Hysteresis:
    """Heating minus cooling of a quantity at the same temperature (gap), with the rate term
    fitted beside it (per unit of the rate regressor) and the points used."""

    gap: float
    gap_ci95: tuple[float, float]
    rate_coeff: float
    rate_coeff_ci95: tuple[float, float]
    n_used: int
    dof: int


def branch_hysteresis(temperature_c, y, sigma, heating, rate, *, order: int = 1, t_ref_c: float = 25.0,
                      guard_c: float = 1.0) -> Hysteresis:
    """The heating-cooling gap of y at the same temperature from a ramp cycle's points (docs/chamber.md,
    "Thermal hysteresis"): weighted least squares of
        y = sum_k a_k (T - t_ref)^k + c rate + gap s / 2,   s = +1 heating, -1 cooling,
    where `rate` is each point's rate regressor (the resonator frequency's rate: forces that trail a
    moving frequency's phase by a part proportional to it make a bias of opposite sign on the two branches that would
    otherwise be taken for hysteresis; the tails and the ramp's start, where the rate changes within a
    branch, separate the two; rate None: no rate term, for a thermometer and drive known not to trail,
    when rate_coeff is 0 and its interval (0, 0)).  Each branch's points within guard_c of its turning
    point (heating: its lowest temperature, cooling: its highest) are left out (a hysteresis loop's corner there is on
    neither branch yet: the guard must exceed the loop's width).  Intervals: the weights' covariance
    widened by the Birge ratio, Student's t on dof."""
    t = np.asarray(temperature_c, dtype=float)
    with_rate = rate is not None
    yv, s = np.asarray(y, dtype=float), np.asarray(sigma, dtype=float)
    r = np.asarray(rate, dtype=float) if with_rate else np.zeros_like(t)
    h = np.asarray(heating, dtype=bool)
    if not (t.shape == yv.shape == s.shape == r.shape == h.shape):
        raise ValueError("temperature, y, sigma, heating and rate must have one length")
    keep = np.zeros(len(t), dtype=bool)
    for branch in (True, False):
        idx = np.flatnonzero(h == branch)
        if len(idx):  # a branch starts at its turning point: heating at its lowest, cooling at its highest
            start = t[idx].min() if branch else t[idx].max()
            keep[idx] = np.abs(t[idx] - start) >= guard_c
    n_up, n_down = int(np.sum(keep & h)), int(np.sum(keep & ~h))
    n_par = order + 2 + int(with_rate)
    if n_up < 2 or n_down < 2 or n_up + n_down <= n_par:
        raise ValueError(f"{n_up} heating and {n_down} cooling points beyond the {guard_c:g} degC guard: "
                         f"2 or more of each and more than {n_par} in all are needed")
    x = t[keep] - t_ref_c
    cols = [np.vander(x, order + 1, increasing=True)] + ([r[keep]] if with_rate else [])
    a = np.column_stack([*cols, np.where(h[keep], 0.5, -0.5)])
    sw = 1.0 / s[keep]
    aw, yw = a * sw[:, None], yv[keep] * sw
    coeffs, *_ = np.linalg.lstsq(aw, yw, rcond=None)
    cov = np.linalg.inv(aw.T @ aw)
    dof = len(x) - n_par
    chi2 = float(np.sum((yw - aw @ coeffs) ** 2))
    half, _ = birge_half_widths(cov, chi2, dof)
    gap = float(coeffs[-1])
    c, c_half = (float(coeffs[-2]), float(half[-2])) if with_rate else (0.0, 0.0)
    return Hysteresis(gap, (gap - float(half[-1]), gap + float(half[-1])), c, (c - c_half, c + c_half), len(x), dof)
