"""The ramp method's analysis (docs/chamber.md, "The ramp method"): segment statistics of a
quantity that moves during its record, the thermometers a ramp offers (the chamber air, the part
thermocouple on the case, the resonator's own frequency) and the heating-cooling gap that shows a
thermometer's lag behind what the resonator feels.  Pure: arrays in, results out."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats

from .thermal_fit import LEVEL, ThermalFit, fit_temperature_polynomial


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
    half = float(stats.t.ppf(0.5 + LEVEL / 2, dof)) * se
    lags = sorted((-(gap - half) / (2 * slope), -(gap + half) / (2 * slope)))
    return BranchGap(gap, (gap - half, gap + half), -gap / (2 * slope), (lags[0], lags[1]))
