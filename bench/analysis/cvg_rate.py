"""The gyro as a rate sensor (IEEE Std 1431's scale factor and drift series), pure analysis:
arrays in, frozen results with 95 % intervals out (docs/cvg_rate_tests.md gives the models).

* `fit_scale_factor(rate_dps, output)`: the outputs averaged at each table rate of a series from
  -R to +R; least squares for the scale factor and bias, nonlinearity (largest residual in ppm of
  full scale) and asymmetry (the positive against the negative rates' scale factor, ppm), with an
  optional nuisance drift and angle distortion with a 90-degree period in the wave's angle
  (whole-angle mode) and an optional bias wandering from the turn-on (generalised least squares).
* `window_output(...)`: one window's output: the mean of a rate output, or the slope of an angle.
* `window_distortion(...)`: what a whole-angle window's rate reads from a 4-theta distortion of
  the angle read-out (unequal pickoff gains), the basis of its rate-proportional terms.
* `static_bias(...)`: the bias of a static record from batch means (or batch slopes of an angle).
* `turn_on_repeatability(...)`: the spread of the bias from turn-on to turn-on, each turn-on's
  estimation noise removed.
* `earth_rate_projection_dph(...)`: Earth's rate on a sensitive axis from a latitude and the
  axis's azimuth and elevation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

EARTH_RATE_DPH = 15.041067  # sidereal rotation, deg/h


def _stats():
    """scipy.stats, imported on first use: the simulators import this module for Earth's rate, and
    scipy.stats costs ~0.4 s of a command's start that never uses it (issue 36)."""
    from scipy import stats

    return stats
LEVEL = 0.95


@dataclass(frozen=True)
class ScaleFactorFit:
    """A scale-factor series' least-squares results; intervals are 95 % (Student's t on the fit's
    residual scatter, whitened for a wandering bias when the windows' times were given).  Output
    units are the output's (deg/s for a rate output, deg/s of wave angle for whole-angle);
    input-referred values are in deg/h."""

    scale_factor: float
    scale_factor_ci95: tuple[float, float]
    bias_out: float  # intercept, output units (Earth's rate included)
    bias_dph: float  # input-referred bias, Earth's rate removed
    bias_dph_ci95: tuple[float, float]
    nonlinearity_ppm: float  # largest |residual| in ppm of full-scale output
    nonlinearity_ppm_ci95: tuple[float, float]
    asymmetry_ppm: float  # (SF+ - SF-) / mean(SF+, SF-), ppm
    asymmetry_ppm_ci95: tuple[float, float]
    full_scale_out: float
    sigma_out: float  # residual scatter of one point, output units
    dof: int
    rate_dps: np.ndarray = field(repr=False)
    output: np.ndarray = field(repr=False)
    fitted: np.ndarray = field(repr=False)
    residual_ppm: np.ndarray = field(repr=False)
    drift_terms: tuple[float, float] | None = None  # whole-angle: (c, s) of the cos/sin 4 theta drift, output units
    distortion_terms: tuple[float, float] | None = None  # whole-angle: (a, b) deg of the angle's sin/cos 4 theta


def _lsq(x: np.ndarray, y: np.ndarray, whiten: np.ndarray | None = None
         ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, int]:
    """Least squares, ordinary or (whiten: L^-1 of the errors' correlation L L^T) generalised:
    (coefficients, covariance, residuals y - x beta, sigma of the whitened residuals, dof)."""
    xw, yw = (x, y) if whiten is None else (whiten @ x, whiten @ y)
    beta, *_ = np.linalg.lstsq(xw, yw, rcond=None)
    dof = len(y) - x.shape[1]
    if dof < 1:
        raise ValueError(f"{len(y)} points for {x.shape[1]} unknowns: too few to estimate the scatter")
    res_w = yw - xw @ beta
    sigma = float(np.sqrt(res_w @ res_w / dof))
    cov = sigma**2 * np.linalg.inv(xw.T @ xw)
    return beta, cov, y - x @ beta, sigma, dof


def wander_whitening(t_mid_s: np.ndarray) -> np.ndarray:
    """L^-1 for window errors that are a random walk of the bias from t = 0 (the turn-on): their
    correlation min(t_i, t_j) = L L^T.  Least squares on L^-1 y is then ordinary least squares on
    the first window's output and the changes from window to window, each over the square root of
    its time step: a constant bias and its wander (rate random walk, the slow part of flicker) do
    not bias it and its intervals hold them; white noise is counted twice per step, which widens."""
    tau = np.asarray(t_mid_s, dtype=float)
    if np.any(tau <= 0.0) or np.any(np.diff(tau) <= 0.0):
        raise ValueError("window times must be positive and increasing (time since the turn-on, in order)")
    return np.linalg.inv(np.linalg.cholesky(np.minimum.outer(tau, tau)))


def _interval(value: float, sd: float, t: float) -> tuple[float, float]:
    return (value - t * sd, value + t * sd)


def level_means(rate: np.ndarray, res: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(rate levels, mean residual at each level (the up and down sweeps' mean), points at each
    level, each point's level index): the points the nonlinearity is read from, and the figure draws."""
    levels, inverse, counts = np.unique(np.round(rate, 9), return_inverse=True, return_counts=True)
    return levels, np.bincount(inverse, weights=res) / counts, counts, inverse


def nonlinearity_ppm(rate: np.ndarray, res: np.ndarray, full_scale: float, sigma_fit: float,
                     dof_fit: int) -> tuple[float, tuple[float, float]]:
    """Largest |mean residual| over the rate levels in ppm of full scale, and a 95 % interval for
    the largest true deviation: |r_g| -/+ t sd(r_g) jointly over the G levels (Bonferroni), sd from
    the pure error within levels when a rate repeats (else the fit's residual scatter)."""
    levels, mean_res, counts, inverse = level_means(rate, res)
    dof_pure = int(np.sum(counts - 1))
    if dof_pure >= 2:
        sigma = math.sqrt(float(np.sum((res - mean_res[inverse]) ** 2)) / dof_pure)
        dof = dof_pure
    else:
        sigma, dof = sigma_fit, dof_fit
    sd = sigma / np.sqrt(counts)
    t_joint = float(_stats().t.ppf(1.0 - (1.0 - LEVEL) / (2 * len(levels)), dof))
    abs_r = np.abs(mean_res)
    scale = 1e6 / full_scale
    lo = float(np.max(np.clip(abs_r - t_joint * sd, 0.0, None))) * scale
    hi = float(np.max(abs_r + t_joint * sd)) * scale
    return float(np.max(abs_r)) * scale, (lo, hi)


def fit_scale_factor(
    rate_dps: np.ndarray, output: np.ndarray, *, drift_basis: np.ndarray | None = None,
    distortion_basis: np.ndarray | None = None, t_mid_s: np.ndarray | None = None, earth_rate_dph: float = 0.0,
) -> ScaleFactorFit:
    """Scale factor, bias, nonlinearity and asymmetry of outputs averaged at table rates.

    Model: output_i = S (rate_i + Earth + B) + [c C_i + s S_i] + [a A_i + b B_i] + e_i.
    drift_basis (m, 2) holds C_i, S_i, the means of cos 4 theta and sin 4 theta over point i's
    window (whole-angle: the damping drift turns with the wave; leave it None when the wave is
    held, where it is one constant with the bias).  distortion_basis (m, 2) holds A_i, B_i, what
    window i's rate reads from an angle read-out distortion a sin 4 theta + b cos 4 theta
    (`window_distortion`; whole-angle: unequal X/Y pickoff gains): a rate-proportional error with a
    90-degree period in the wave angle that windows of whole table turns do not average out.
    Errors: with t_mid_s (the windows' mid times since the turn-on, increasing) e_i is a random
    walk of the bias from the turn-on (`wander_whitening`: rate random walk and flicker make
    neighbouring windows' errors alike, which ordinary least squares reads as 2-3x too little
    scatter on the scale factor), fitted by generalised least squares; without, independent with a
    common variance.  Intervals: Student's t on the (whitened) residuals.  Asymmetry: the same
    model with separate slopes for positive and negative rates.  Nonlinearity: `nonlinearity_ppm`
    of the residuals, full scale |S| R with R = max |rate|."""
    rate = np.asarray(rate_dps, dtype=float)
    y = np.asarray(output, dtype=float)
    m = len(rate)
    cols = [np.ones(m), rate]
    for basis in (drift_basis, distortion_basis):
        if basis is not None:
            basis = np.asarray(basis, dtype=float).reshape(m, 2)
            cols += [basis[:, 0], basis[:, 1]]
    whiten = None if t_mid_s is None else wander_whitening(t_mid_s)
    x = np.column_stack(cols)
    beta, cov, res, _sigma_w, dof = _lsq(x, y, whiten)
    sigma = float(np.sqrt(res @ res / dof))  # one window's scatter about the line, output units
    t = float(_stats().t.ppf(0.5 + LEVEL / 2, dof))
    b, s = float(beta[0]), float(beta[1])
    sf_ci = _interval(s, math.sqrt(cov[1, 1]), t)
    # input-referred bias b / S - Earth (delta method)
    grad = np.array([1.0 / s, -b / s**2])
    var_ratio = float(grad @ cov[:2, :2] @ grad)
    bias_dps = b / s - earth_rate_dph / 3600.0
    bias_ci = tuple(3600.0 * v for v in _interval(bias_dps, math.sqrt(var_ratio), t))
    # nonlinearity: the residuals averaged over the windows at each rate (both directions), with the
    # scatter within those groups (pure error: a deviation from the line that the rate sets cancels
    # in it) when rates repeat, else the fit's residual scatter
    full_scale = abs(s) * float(np.max(np.abs(rate)))
    nl, nl_ci = nonlinearity_ppm(rate, res, full_scale, sigma, dof)
    # asymmetry: separate slopes above and below zero rate
    xa = np.column_stack([np.ones(m), np.clip(rate, 0.0, None), np.clip(rate, None, 0.0), *cols[2:]])
    asym, asym_ci = float("nan"), (float("nan"), float("nan"))
    if (rate > 0).sum() >= 1 and (rate < 0).sum() >= 1 and m - xa.shape[1] >= 1:
        ba, ca, _, _, dof_a = _lsq(xa, y, whiten)
        sp, sn = float(ba[1]), float(ba[2])
        mean = 0.5 * (sp + sn)
        asym = (sp - sn) / mean * 1e6
        g = np.array([1.0 / mean - (sp - sn) / (2 * mean**2), -1.0 / mean - (sp - sn) / (2 * mean**2)]) * 1e6
        sd_a = math.sqrt(float(g @ ca[1:3, 1:3] @ g))
        asym_ci = _interval(asym, sd_a, float(_stats().t.ppf(0.5 + LEVEL / 2, dof_a)))
    fitted = x @ beta
    return ScaleFactorFit(
        scale_factor=s, scale_factor_ci95=sf_ci, bias_out=b, bias_dph=3600.0 * bias_dps, bias_dph_ci95=bias_ci,
        nonlinearity_ppm=nl, nonlinearity_ppm_ci95=nl_ci, asymmetry_ppm=asym, asymmetry_ppm_ci95=asym_ci,
        full_scale_out=full_scale, sigma_out=sigma, dof=dof, rate_dps=rate, output=y, fitted=fitted,
        residual_ppm=res / full_scale * 1e6,
        drift_terms=None if drift_basis is None else (float(beta[2]), float(beta[3])),
        distortion_terms=None if distortion_basis is None else (float(beta[-2]), float(beta[-1])),
    )


def window_output(t_s: np.ndarray, rate_out_dps: np.ndarray, angle_out_deg: np.ndarray, mode: str,
                  box_s: float = 0.0) -> tuple[float, float, float]:
    """One window's output and the means of cos 4 theta, sin 4 theta over it, each weighted as the
    output weighs the rate along the window, so an angle-dependent drift enters both alike:
    * force-to-rebalance: the mean rate output (uniform weights);
    * whole-angle, box_s > 0: the change of the angle's mean over the first and the last box_s of
      the window divided by the time between them (a trapezoid weight on the angle's rate); when
      that time is whole table turns the table's angle ripple, the same in both boxes, cancels;
    * whole-angle, box_s = 0: the least-squares slope of the angle, a mean of its rate with the
      parabolic weight (t - t_0)(t_end - t) (summation by parts)."""
    theta = np.radians(np.asarray(angle_out_deg, dtype=float))
    t = np.asarray(t_s, dtype=float)
    ang = np.asarray(angle_out_deg, dtype=float)
    if mode == "force-to-rebalance":
        return float(np.mean(rate_out_dps)), float(np.mean(np.cos(4 * theta))), float(np.mean(np.sin(4 * theta)))
    nb = int(np.sum(t <= t[0] + box_s - 1e-9)) if box_s > 0 else 0
    if 1 <= nb <= len(t) // 2:
        c = _box_weights(len(t), nb)  # m2 - m1 = sum_k c_k (theta_k+1 - theta_k)
        dt = np.diff(t)
        span = float(c @ dt)
        rate = float(ang[-nb:].mean() - ang[:nb].mean()) / span
        mid = 0.5 * (theta[1:] + theta[:-1])
        w = c * dt / span
        return rate, float(w @ np.cos(4 * mid)), float(w @ np.sin(4 * mid))
    w = (t - t[0]) * (t[-1] - t)
    w = w / w.sum()
    slope = float(np.polyfit(t - t.mean(), ang, 1)[0])
    return slope, float(w @ np.cos(4 * theta)), float(w @ np.sin(4 * theta))


def window_distortion(t_s: np.ndarray, angle_out_deg: np.ndarray, box_s: float = 0.0) -> tuple[float, float]:
    """What one whole-angle window's rate (`window_output`, same box_s) reads from an angle
    read-out distortion a sin 4 theta + b cos 4 theta (deg; unequal X/Y pickoff gains g_x, g_y give
    a = degrees((g_y - g_x) / 4)): (A, B), the change of sin 4 theta and cos 4 theta the window's
    rate sees (the box means' difference over the time between them, or their least-squares
    slope), so the window reads a A + b B more.  Per unit rate it goes as the mean of
    4 cos 4 theta over the wave's travel: a scale-factor error that a window of whole table turns
    (not whole 90-degree periods of the wave) keeps, the same sign every run."""
    t = np.asarray(t_s, dtype=float)
    four_theta = 4.0 * np.radians(np.asarray(angle_out_deg, dtype=float))
    s4, c4 = np.sin(four_theta), np.cos(four_theta)
    nb = int(np.sum(t <= t[0] + box_s - 1e-9)) if box_s > 0 else 0
    if 1 <= nb <= len(t) // 2:
        span = float(_box_weights(len(t), nb) @ np.diff(t))
        return float(s4[-nb:].mean() - s4[:nb].mean()) / span, float(c4[-nb:].mean() - c4[:nb].mean()) / span
    tc = t - t.mean()
    return float(np.polyfit(tc, s4, 1)[0]), float(np.polyfit(tc, c4, 1)[0])


def _box_weights(n: int, nb: int) -> np.ndarray:
    """c_k of m2 - m1 = sum_k c_k (x_k+1 - x_k), m1, m2 the means of the first and last nb of n
    samples: (#box-2 samples after k - #box-1 samples after k) / nb."""
    idx = np.arange(n - 1)
    after1 = np.clip(nb - 1 - idx, 0, None)
    after2 = np.clip(n - 1 - np.maximum(idx, n - 1 - nb), 0, nb)
    return (after2 - after1) / nb


@dataclass(frozen=True)
class BiasEstimate:
    """A static record's input-referred bias (deg/h, Earth's rate removed) with its 95 % interval
    from n_batches batch means (batch slopes of the angle in whole-angle mode)."""

    bias_dph: float
    ci95: tuple[float, float]
    sigma_dph: float  # standard error of bias_dph
    n_batches: int
    batch_dph: np.ndarray = field(repr=False)


def static_bias(
    t_s: np.ndarray, out: np.ndarray, *, mode: str, scale_factor: float, earth_rate_dph: float = 0.0,
    n_batches: int = 10,
) -> BiasEstimate:
    """Bias of a static record: out is the rate output (force-to-rebalance) or the angle (whole-angle,
    deg); each of n_batches equal batches gives a mean rate (the batch's mean output, or the slope of
    its angle), divided by the scale factor; the bias is their mean, its interval Student's t on their
    scatter (batches of a record much longer than the loops' settling are nearly independent)."""
    t = np.asarray(t_s, dtype=float)
    y = np.asarray(out, dtype=float)
    if n_batches < 2 or len(t) < 2 * n_batches:
        raise ValueError(f"{len(t)} samples for {n_batches} batches: need 2 or more batches of 2 samples or more")
    edges = np.linspace(0, len(t), n_batches + 1).astype(int)
    rates = []
    for i0, i1 in zip(edges[:-1], edges[1:], strict=True):
        if mode == "force-to-rebalance":
            rates.append(float(np.mean(y[i0:i1])))
        else:
            tb = t[i0:i1]
            rates.append(float(np.polyfit(tb - tb.mean(), y[i0:i1], 1)[0]))
    batch = np.asarray(rates) / scale_factor * 3600.0 - earth_rate_dph
    mean = float(batch.mean())
    se = float(batch.std(ddof=1) / math.sqrt(n_batches))
    tq = float(_stats().t.ppf(0.5 + LEVEL / 2, n_batches - 1))
    return BiasEstimate(mean, _interval(mean, se, tq), se, n_batches, batch)


@dataclass(frozen=True)
class Repeatability:
    """The bias's spread from turn-on to turn-on (1 sigma, deg/h), each turn-on's own estimation
    noise removed, with its 95 % interval; the mean bias over the turn-ons with its interval."""

    sigma_dph: float
    ci95: tuple[float, float]
    std_dph: float  # plain standard deviation of the turn-on biases
    mean_dph: float
    mean_ci95: tuple[float, float]
    n: int


def turn_on_repeatability(bias_dph: np.ndarray, sigma_dph: np.ndarray) -> Repeatability:
    """Turn-on biases b_i with their standard errors s_i: var(b) = spread^2 + mean(s_i^2), so the
    spread is sqrt(var - mean s^2) with var's chi-square interval (n - 1 degrees of freedom) shifted
    the same way and clipped at zero.  The mean's interval is Student's t on the biases' scatter, or
    the records' own noise when that is larger."""
    b = np.asarray(bias_dph, dtype=float)
    s = np.asarray(sigma_dph, dtype=float)
    n = len(b)
    if n < 2:
        raise ValueError(f"{n} turn-on(s): repeatability needs 2 or more")
    var = float(b.var(ddof=1))
    noise = float(np.mean(s**2))
    dof = n - 1
    lo_var = var * dof / float(_stats().chi2.ppf(0.5 + LEVEL / 2, dof))
    hi_var = var * dof / float(_stats().chi2.ppf(0.5 - LEVEL / 2, dof))
    spread = math.sqrt(max(var - noise, 0.0))
    ci = (math.sqrt(max(lo_var - noise, 0.0)), math.sqrt(max(hi_var - noise, 0.0)))
    mean = float(b.mean())
    # the mean's standard error: the turn-ons' scatter (Student's t, n - 1 degrees of freedom), but
    # never below the records' own noise (a few turn-ons can agree by chance far closer than that)
    se_scatter, se_noise = math.sqrt(var / n), math.sqrt(noise / n)
    if se_scatter >= se_noise:
        half = float(_stats().t.ppf(0.5 + LEVEL / 2, dof)) * se_scatter
    else:
        half = float(_stats().norm.ppf(0.5 + LEVEL / 2)) * se_noise
    return Repeatability(spread, ci, math.sqrt(var), mean, (mean - half, mean + half), n)


def earth_rate_projection_dph(latitude_deg: float, azimuth_deg: float = 0.0, elevation_deg: float = 90.0) -> float:
    """Earth's rate on a sensitive axis at a latitude, the axis given by its azimuth (from north
    towards east) and elevation (above the horizon): 15.041 (cos lat cos el cos az + sin lat sin el)
    deg/h; up gives 15.041 sin lat, north 15.041 cos lat, east 0."""
    lat, az, el = (math.radians(v) for v in (latitude_deg, azimuth_deg, elevation_deg))
    return EARTH_RATE_DPH * (math.cos(lat) * math.cos(el) * math.cos(az) + math.sin(lat) * math.sin(el))
