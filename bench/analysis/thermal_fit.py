"""Polynomial fits of a quantity against temperature for thermal calibration (docs/chamber.md):
weighted least squares on the points' own standard errors, the order chosen by the Bayesian
information criterion, 95 % intervals on the coefficients.  Pure: arrays in, a result out."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


def _stats():
    """scipy.stats, imported on first use: a process that only loads the procedures (the line's
    limits, `gyrobench list`) never pays its ~0.4 s (issue 36)."""
    from scipy import stats

    return stats


LEVEL = 0.95


@dataclass(frozen=True)
class ThermalFit:
    """y(T) = sum_k coeffs[k] (T - t_ref_c)**k, the order chosen by BIC.

    ci95: (order + 1, 2) intervals of the coefficients; bic: BIC of each order tried;
    birge: sqrt(chi2 / dof) of the chosen fit (> 1: the points scatter more than their own errors,
    and the intervals are widened by it with Student's t on dof); residuals: y - fit."""

    order: int
    coeffs: np.ndarray
    ci95: np.ndarray
    t_ref_c: float
    bic: dict[int, float]
    birge: float
    dof: int
    residuals: np.ndarray
    #: the coefficients' covariance, scaled by birge**2 where the scatter exceeds the stated errors
    cov: np.ndarray | None = None

    def __call__(self, temperature_c) -> np.ndarray:
        x = np.asarray(temperature_c, dtype=float) - self.t_ref_c
        return np.polynomial.polynomial.polyval(x, self.coeffs)

    def se_at(self, temperature_c) -> np.ndarray:
        """Standard error of the fitted curve at temperature_c (the coefficients' covariance carried):
        what the fit's own uncertainty leaves in a compensation made from it."""
        if self.cov is None:
            raise ValueError("this fit carries no covariance")
        x = np.atleast_1d(np.asarray(temperature_c, dtype=float)) - self.t_ref_c
        basis = np.vander(x, self.order + 1, increasing=True)
        return np.sqrt(np.einsum("ij,jk,ik->i", basis, self.cov, basis))

    def slope_at(self, temperature_c: float) -> float:
        """dy/dT at a temperature."""
        der = np.polynomial.polynomial.polyder(self.coeffs)
        return float(np.polynomial.polynomial.polyval(temperature_c - self.t_ref_c, der)) if len(der) else 0.0


def _wls(x: np.ndarray, y: np.ndarray, w: np.ndarray, order: int) -> tuple[np.ndarray, np.ndarray, float]:
    """Coefficients, their covariance (from the weights alone) and chi2 of one order."""
    a = np.vander(x, order + 1, increasing=True)
    aw = a * np.sqrt(w)[:, None]
    yw = y * np.sqrt(w)
    coeffs, *_ = np.linalg.lstsq(aw, yw, rcond=None)
    cov = np.linalg.inv(aw.T @ aw)
    chi2 = float(np.sum((yw - aw @ coeffs) ** 2))
    return coeffs, cov, chi2


def birge_half_widths(cov: np.ndarray, chi2: float, dof: int) -> tuple[np.ndarray, float]:
    """95 % half-widths of a weighted fit's coefficients and its Birge ratio sqrt(chi2/dof): when the
    scatter exceeds the stated errors (ratio > 1) the covariance is scaled up and Student's t taken."""
    birge = math.sqrt(chi2 / dof) if dof > 0 else 1.0
    if birge > 1.0:
        cov = cov * birge**2
        q = float(_stats().t.ppf(0.5 + LEVEL / 2, dof))
    else:
        q = float(_stats().norm.ppf(0.5 + LEVEL / 2))
    return q * np.sqrt(np.diag(cov)), birge


def fit_temperature_polynomial(
    temperature_c, y, sigma, *, max_order: int = 3, t_ref_c: float = 25.0, min_order: int = 0,
    sigma_t_c: float = 0.0,
) -> ThermalFit:
    """Fit y against temperature: orders min_order..max_order (each leaving one degree of freedom or more),
    BIC = chi2 + (order + 1) ln n on the points' standard errors `sigma`, the lowest BIC taken.
    Intervals: the weights' covariance, widened by the Birge ratio when the scatter exceeds the
    points' errors (then Student's t on the degrees of freedom, else the normal quantile).
    sigma_t_c: the temperature readings' own standard error (a 0.1 degC display: 0.1 / sqrt(12)),
    carried into y as the effective variance sigma^2 + (dy/dT sigma_t)^2, dy/dT from each order's
    own fit (iterated twice), so a steep quantity does not take a higher order to chase the
    thermometer's steps (the BIC then compares chi2 on each order's own effective weights)."""
    t = np.asarray(temperature_c, dtype=float)
    yv = np.asarray(y, dtype=float)
    s = np.asarray(sigma, dtype=float)
    n = len(t)
    if n < 2 or yv.shape != t.shape or s.shape != t.shape:
        raise ValueError(f"{n} points (temperature, y, sigma of one length, 2 or more) are needed")
    if not np.all(np.isfinite(s)) or np.any(s <= 0):
        raise ValueError("every sigma must be finite and > 0")
    x = t - t_ref_c
    w = 1.0 / s**2
    distinct = len(np.unique(np.round(t, 9)))
    top = min(int(max_order), n - 2, distinct - 1)  # an order needs that many + 1 distinct temperatures
    if min_order > top:
        raise ValueError(f"order {min_order} needs {min_order + 2} points at {min_order + 1} temperatures or more; "
                         f"{n} points at {distinct} temperatures given")
    fits = {}
    for k in range(int(min_order), top + 1):
        fit = _wls(x, yv, w, k)
        for _ in range(2 if sigma_t_c > 0 else 0):
            slope = np.polynomial.polynomial.polyval(x, np.polynomial.polynomial.polyder(fit[0])) if k else 0.0
            fit = _wls(x, yv, 1.0 / (s**2 + (slope * sigma_t_c) ** 2), k)
        fits[k] = fit
    bic = {k: chi2 + (k + 1) * math.log(n) for k, (_, _, chi2) in fits.items()}
    order = min(bic, key=bic.get)
    coeffs, cov, chi2 = fits[order]
    dof = n - order - 1
    half, birge = birge_half_widths(cov, chi2, dof)
    ci = np.column_stack([coeffs - half, coeffs + half])
    resid = yv - np.polynomial.polynomial.polyval(x, coeffs)
    return ThermalFit(order, coeffs, ci, float(t_ref_c), bic, birge, dof, resid, cov * max(birge, 1.0) ** 2)


def batch_mean(values, n_batches: int = 10) -> tuple[float, float]:
    """Mean of a record and its standard error from the scatter of n_batches batch means
    (batches much longer than the correlation time are nearly independent)."""
    v = np.asarray(values, dtype=float)
    if n_batches < 2 or len(v) < 2 * n_batches:
        raise ValueError(f"{len(v)} samples for {n_batches} batches: need 2 or more samples a batch")
    means = np.array([b.mean() for b in np.array_split(v, n_batches)])
    return float(means.mean()), float(means.std(ddof=1) / math.sqrt(n_batches))
