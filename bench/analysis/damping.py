"""Damping non-uniformity of an HRG from a free decay on a rate table (PHYSICS.md section 3).

The estimators work on the four demodulated slow variables (cx, sx, cy, sy) after the drive is cut:

* log-linear least squares on ln E (closed form, weighted for the noise: var(ln E) = 4 s^2 / E);
* the patent's Gauss-Newton on E itself, batch or sequential (`SequentialDampingFit`), in the
  (b_c, b_s) parametrisation so that its start at D = 0 is not singular.

Two energy models are offered.  "patent": d ln E/dt = -gamma - b_c cos 4th - b_s sin 4th, with
th the measured wave angle.  "exact" (default): for the linear model without forcing,
    dE/dt = -gamma E - b_c R - b_s S + n Q        (R, S, Q the invariants of PHYSICS.md section 1)
holds exactly whatever the rate, frequency split or quadrature (the split and the Coriolis terms
are conservative), so d ln E/dt = -gamma - b_c R/E - b_s S/E.  R/E = rho cos 4th with
rho = (a^2 - k^2)/E, so the exact model is the patent's with the quadrature factor rho; it removes
the bias that a split and quadrature give the patent's model at low table rates.  The circulatory
term n Q/E is left out: with a constant quadrature it is collinear with gamma.
Per-step integrals are exact for an angle that is linear in time within a step (PHYSICS.md
pitfall (c)).  Results are frozen dataclasses; nothing here touches a device, a clock or a file.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import lru_cache
from types import MappingProxyType
from typing import Any

import numpy as np

from .axes import axis_deg


def _optimize() -> Any:
    """scipy.optimize on first use: a report that only reads a damping run's results does not pay
    its import (~0.4 s of CPU; benchmarks/report_speed.py)."""
    from scipy import optimize

    return optimize


def _special() -> Any:
    """scipy.special on first use (stdtrit: Student t quantiles without importing scipy.stats, ~1 s)."""
    from scipy import special

    return special

#: Parameter vector of every fit, in this order: ln E at t0, gamma = 2/tau, b_c, b_s.
PARAM_NAMES = ("ln_e0", "gamma_per_s", "b_c_per_s", "b_s_per_s")
METHODS = ("log-linear", "gauss-newton", "gauss-newton-unweighted")
MODELS = ("exact", "patent")
CI_NAMES = ("theta_tau_deg", "delta_inv_tau_per_s", "tau_s")
_MIN_SAMPLES = 8


class DampingFitError(ValueError):
    """The decay data cannot be fitted (too short, non-finite, zero energy, bad option)."""


# ----------------------------------------------------------------------------------------------
# Regressors

_MAX_STEP_RAD = 2.8  # 4 theta may turn at most this far between samples (beyond: aliasing)


@dataclass(frozen=True)
class DecayRegressors:
    """Per-sample quantities of a decay: time since start, energy and its log, unwrapped 4 theta,
    and the design matrix X = (1, -t, -C, -S), C and S the cumulative damping integrals."""

    t_rel_s: np.ndarray
    energy: np.ndarray
    ln_e: np.ndarray
    phi_rad: np.ndarray  # 4 theta, unwrapped (rad)
    xt: np.ndarray  # (4, n) transposed design matrix: ln E = (ln_e0, gamma, b_c, b_s) @ xt

    @property
    def x(self) -> np.ndarray:
        """The design matrix X (n, 4), a view."""
        return self.xt.T

    @property
    def c_int_s(self) -> np.ndarray:
        """Integral of rho cos 4 theta since the first sample (s)."""
        return -self.xt[2]

    @property
    def s_int_s(self) -> np.ndarray:
        return -self.xt[3]

    def design(self) -> np.ndarray:
        return self.x


def _as_channels(t_s, cx, sx, cy, sy, *, min_samples: int = _MIN_SAMPLES) -> tuple[np.ndarray, ...]:
    arrays = [np.asarray(a, dtype=float).reshape(-1) for a in (t_s, cx, sx, cy, sy)]
    n = arrays[0].size
    for name, a in zip(("t_s", "cx", "sx", "cy", "sy"), arrays, strict=True):
        if a.size != n:
            raise DampingFitError(f"{name} has {a.size} samples but t_s has {n}; all five must match")
        if not np.isfinite(a).all():
            raise DampingFitError(f"{name} contains non-finite values")
    if n < min_samples:
        raise DampingFitError(f"decay has {n} samples; at least {min_samples} are needed")
    if n > 1 and not (np.diff(arrays[0]) > 0).all():
        raise DampingFitError("t_s must be strictly increasing")
    return tuple(arrays)


def _sample_parts(cx, sx, cy, sy, model: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Energy, wrapped 4 theta, and the model's damping modulation (rho cos 4th, rho sin 4th):
    (R/E, S/E) for the exact model, (cos 4th, sin 4th) for the patent's."""
    xx = cx * cx + sx * sx
    yy = cy * cy + sy * sy
    energy = xx + yy
    if not (energy > 0).all():
        raise DampingFitError("the energy E = cx^2+sx^2+cy^2+sy^2 is zero at some sample")
    r_inv = xx - yy
    s_inv = 2.0 * (cx * cy + sx * sy)
    phi = np.arctan2(s_inv, r_inv)
    norm = energy if model == "exact" else np.sqrt(r_inv * r_inv + s_inv * s_inv)
    return energy, phi, r_inv / norm, s_inv / norm


def _step_integrals(dt, phi, mc, ms) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-step increments of 4 theta and the exact integrals of the modulation over each step.

    With 4 theta linear within a step, integral of rho cos 4th = dt rho sin(h)/h cos(mid), h half
    the step, which equals the trapezoid rule times tan(h)/h (PHYSICS.md pitfall (c))."""
    d = np.diff(phi)
    d = (d + math.pi) % (2.0 * math.pi) - math.pi
    h = 0.5 * d
    if h.size and np.abs(h).max() > 0.5 * _MAX_STEP_RAD:
        raise DampingFitError(
            f"the wave angle 4 theta turns {2 * np.abs(h).max():.2f} rad between two samples (limit "
            f"{_MAX_STEP_RAD} rad): the stream is too slow for the table rate, or the signal is lost in noise"
        )
    small = np.abs(h) < 1e-4
    f = np.tan(h) / np.where(small, 1.0, h)
    f[small] = 1.0 + h[small] ** 2 / 3.0
    g = 0.5 * dt * f
    return d, g * (mc[1:] + mc[:-1]), g * (ms[1:] + ms[:-1])


def decay_regressors(t_s, cx, sx, cy, sy, *, model: str = "exact") -> DecayRegressors:
    """Energy, unwrapped 4 theta and the design matrix of a recorded decay."""
    if model not in MODELS:
        raise DampingFitError(f"model={model!r} is not one of {MODELS}")
    t, cx, sx, cy, sy = _as_channels(t_s, cx, sx, cy, sy)
    energy, phi, mc, ms = _sample_parts(cx, sx, cy, sy, model)
    d, dc, ds = _step_integrals(np.diff(t), phi, mc, ms)
    n = t.size
    xt = np.empty((4, n))
    xt[0] = 1.0
    np.subtract(t[0], t, out=xt[1])
    xt[2:, 0] = 0.0
    np.cumsum(dc, out=xt[2, 1:])
    np.cumsum(ds, out=xt[3, 1:])
    xt[2:] *= -1.0
    phi_u = np.empty(n)
    phi_u[0] = phi[0]
    np.cumsum(d, out=phi_u[1:])
    phi_u[1:] += phi[0]
    return DecayRegressors(t_rel_s=-xt[1], energy=energy, ln_e=np.log(energy), phi_rad=phi_u, xt=xt)


# ----------------------------------------------------------------------------------------------
# Results


@dataclass(frozen=True)
class DampingFit:
    """A fitted free decay: the damping axis, anisotropy and time constant with 95 % intervals.

    theta_tau_deg in [0, 90) is the most damped axis; delta_inv_tau_per_s = 1/tau1 - 1/tau2 >= 0;
    tau_s the mean amplitude time constant.  ci95 maps exactly those three names to (low, high);
    the theta interval is centre +- half-width and may leave [0, 90).  `params` and `covariance`
    are over PARAM_NAMES.  Arrays are for plots: energy and its fit, ln E residuals, theta(t).
    """

    theta_tau_deg: float
    delta_inv_tau_per_s: float
    tau_s: float
    ci95: Mapping[str, tuple[float, float]]
    std: Mapping[str, float]
    method: str
    model: str
    params: np.ndarray
    covariance: np.ndarray
    noise_sigma: float
    n_samples: int
    iterations: int
    converged: bool
    t_s: np.ndarray = field(repr=False)
    energy: np.ndarray = field(repr=False)
    energy_fit: np.ndarray = field(repr=False)
    residuals_ln_e: np.ndarray = field(repr=False)
    theta_rad: np.ndarray = field(repr=False)

    @property
    def gamma_per_s(self) -> float:
        return float(self.params[1])

    @property
    def b_c_per_s(self) -> float:
        return float(self.params[2])

    @property
    def b_s_per_s(self) -> float:
        return float(self.params[3])

    @property
    def drift_amplitude_rad_s(self) -> float:
        """Amplitude of the wave's angle-dependent drift, D/4 (rad/s, wave frame)."""
        return 0.25 * self.delta_inv_tau_per_s

    def q_factor(self, f0_hz: float) -> float:
        """Q = pi f0 tau."""
        return math.pi * f0_hz * self.tau_s

    def q_factor_ci95(self, f0_hz: float) -> tuple[float, float]:
        lo, hi = self.ci95["tau_s"]
        return (math.pi * f0_hz * lo, math.pi * f0_hz * hi)

    def drift_amplitude_dph(self, bryan_factor: float) -> float:
        """Output-referred amplitude of the angle-dependent drift, (D/4)/K in deg/h."""
        if not bryan_factor > 0:
            raise ValueError(f"bryan_factor={bryan_factor!r} must be > 0")
        return math.degrees(self.drift_amplitude_rad_s / bryan_factor) * 3600.0

    def summary(self) -> str:
        ci = self.ci95
        return (
            f"{self.method} ({self.model} model, {self.n_samples} samples): "
            f"theta_tau {self.theta_tau_deg:.3f} deg [{ci['theta_tau_deg'][0]:.3f}, {ci['theta_tau_deg'][1]:.3f}], "
            f"Delta(1/tau) {self.delta_inv_tau_per_s:.4e} 1/s "
            f"[{ci['delta_inv_tau_per_s'][0]:.4e}, {ci['delta_inv_tau_per_s'][1]:.4e}], "
            f"tau {self.tau_s:.3f} s [{ci['tau_s'][0]:.3f}, {ci['tau_s'][1]:.3f}], noise {self.noise_sigma:.3g}"
        )


_PHI_GRID = np.linspace(0.0, 2.0 * math.pi, 512, endpoint=False)
_UNIT = np.stack([np.cos(_PHI_GRID), np.sin(_PHI_GRID)])  # (2, m) directions of the damping vector
_FAR_SIGMAS = 40.0  # the belt is tabulated to |b|/sigma = 40 (s = 1.9596 there; 1.95996 is the normal's)
_GAUSS_SIGMAS = 20.0  # beyond |b| = 20 sigma the delta-method interval (s(20) = 1.9593, bias sigma/40)


@lru_cache(maxsize=4)
def _belt_table(level: float) -> tuple[np.ndarray, np.ndarray]:
    """(r, s(r)): for a damping vector of length r (in standard errors) measured with isotropic
    Gaussian noise, |b_hat| is Rice-distributed and P(|  |b_hat| - r | <= s) = level (noncentral
    chi^2 with 2 dof); s(0) = sqrt(chi2_2 quantile) = 2.45 at 95 %, s -> normal quantile as r grows."""
    r = np.linspace(0.0, _FAR_SIGMAS, 801)
    s = np.empty_like(r)
    for i, ri in enumerate(r):
        def cover(x: float, ri: float = ri) -> float:
            low = _special().chndtr((ri - x) ** 2, 2, ri * ri) if x < ri else 0.0
            return float(_special().chndtr((ri + x) ** 2, 2, ri * ri) - low) - level

        s[i] = _optimize().brentq(cover, 0.0, 20.0, xtol=1e-10)
    return r, s


def _profile_chi2(b: np.ndarray, w: np.ndarray, d0: np.ndarray) -> np.ndarray:
    """min over the axis of (b_hat - D0 u)^T W (b_hat - D0 u) for each D0 (the profile likelihood
    ratio statistic of D0 with the axis a nuisance): a 512-point grid refined by a parabola."""
    d0 = np.atleast_1d(np.asarray(d0, dtype=float))
    diff = b[:, None, None] - d0[None, :, None] * _UNIT[:, None, :]  # (2, nD, m)
    chi2 = np.einsum("ij,ikm,jkm->km", w, diff, diff)
    i = np.argmin(chi2, axis=1)
    rows = np.arange(d0.size)
    m = _PHI_GRID.size
    lo, mid, hi = chi2[rows, (i - 1) % m], chi2[rows, i], chi2[rows, (i + 1) % m]
    curv = lo - 2.0 * mid + hi
    with np.errstate(divide="ignore", invalid="ignore"):
        shift = np.where(curv > 0, 0.5 * (lo - hi) / curv, 0.0)
    return np.maximum(mid - 0.25 * (lo - hi) * shift, 0.0)


def delta_interval(b: np.ndarray, cov_b: np.ndarray, level: float = 0.95) -> tuple[float, float]:
    """Interval of D = |(b_c, b_s)| >= 0 that keeps its coverage as D -> 0: the Neyman belt of the
    profile likelihood ratio (Feldman-Cousins ordering; the axis is a nuisance), calibrated by the
    Rice distribution of |b_hat| for the isotropic noise sqrt(det cov)^(1/2) (docs/free_decay_identification.md).
    The naive |b| +- 1.96 sigma covers only P(chi2_2 <= 3.84) = 85 % at D = 0."""
    b = np.asarray(b, dtype=float)
    cov_b = 0.5 * (np.asarray(cov_b, dtype=float) + np.asarray(cov_b, dtype=float).T)
    d = float(math.hypot(b[0], b[1]))
    det = float(np.linalg.det(cov_b))
    sig_max = math.sqrt(max(float(np.linalg.eigvalsh(cov_b)[-1]), 0.0))
    if not (det > 0 and sig_max > 0 and math.isfinite(d)):
        return (d, d) if sig_max == 0 else (0.0, math.inf)
    sig = det**0.25
    r_tab, s_tab = _belt_table(float(level))
    if d > _GAUSS_SIGMAS * sig_max:  # far from zero: the Gaussian (delta-method) interval
        g = b / d
        sd = math.sqrt(max(float(g @ cov_b @ g), 0.0))
        k = float(_special().ndtri(0.5 * (1.0 + level)))
        return d - k * sd, d + k * sd
    w = np.linalg.inv(cov_b)

    def excess(d0: np.ndarray) -> np.ndarray:
        s = np.interp(np.asarray(d0) / sig, r_tab, s_tab, right=s_tab[-1])
        return _profile_chi2(b, w, d0) - s * s

    def f(d0: float) -> float:
        return float(excess(np.array([d0]))[0])

    # the accepted set is an interval around |b_hat| (excess < 0 there): its ends by Brent's method
    tol = 1e-6 * sig
    low = 0.0 if f(0.0) <= 0.0 else _optimize().brentq(f, 0.0, d, xtol=tol)
    high = _optimize().brentq(f, d, d + 10.0 * sig_max, xtol=tol)
    return float(low), float(high)


def _physical(params: np.ndarray, cov: np.ndarray, dof: int) -> tuple[dict, dict, dict]:
    """(ln_e0, gamma, b_c, b_s) and their covariance -> theta_tau, D, tau with delta-method std."""
    gamma, b_c, b_s = (float(v) for v in params[1:])
    d = math.hypot(b_c, b_s)
    theta_deg = axis_deg(math.degrees(0.25 * math.atan2(b_s, b_c)))
    tau = 2.0 / gamma if gamma > 0 else math.inf
    g_tau = np.array([0.0, -2.0 / gamma**2 if gamma > 0 else 0.0, 0.0, 0.0])
    if d > 0:
        g_d = np.array([0.0, 0.0, b_c / d, b_s / d])
        g_th = np.array([0.0, 0.0, -b_s, b_c]) * (0.25 / d**2) * (180.0 / math.pi)
    else:
        g_d = np.zeros(4)
        g_th = np.zeros(4)
    std = {
        "theta_tau_deg": math.sqrt(max(float(g_th @ cov @ g_th), 0.0)) if d > 0 else math.inf,
        "delta_inv_tau_per_s": math.sqrt(max(float(g_d @ cov @ g_d), 0.0))
        if d > 0
        else math.sqrt(max(0.5 * (cov[2, 2] + cov[3, 3]), 0.0)),
        "tau_s": math.sqrt(max(float(g_tau @ cov @ g_tau), 0.0)),
    }
    k = float(_special().stdtrit(max(dof, 1), 0.975))
    value = {"theta_tau_deg": theta_deg, "delta_inv_tau_per_s": d, "tau_s": tau}
    ci = {
        "theta_tau_deg": (theta_deg - k * std["theta_tau_deg"], theta_deg + k * std["theta_tau_deg"]),
        "delta_inv_tau_per_s": delta_interval(np.array([b_c, b_s]), cov[2:4, 2:4]),
        "tau_s": (tau - k * std["tau_s"], tau + k * std["tau_s"]),
    }
    return value, std, ci


def _make_result(
    reg: DecayRegressors,
    t_s: np.ndarray,
    params: np.ndarray,
    cov: np.ndarray,
    noise_sigma: float,
    method: str,
    model: str,
    iterations: int,
    converged: bool,
    *,
    curves: bool = True,
) -> DampingFit:
    n = reg.energy.size
    dof = n - len(PARAM_NAMES)
    value, std, ci = _physical(params, cov, dof)
    if curves:
        ln_fit = _lin(params, reg.xt)
        arrays = (np.array(t_s, dtype=float), reg.energy.copy(), np.exp(ln_fit), reg.ln_e - ln_fit, 0.25 * reg.phi_rad)
    else:
        arrays = tuple(np.empty(0) for _ in range(5))
    return DampingFit(
        theta_tau_deg=value["theta_tau_deg"],
        delta_inv_tau_per_s=value["delta_inv_tau_per_s"],
        tau_s=value["tau_s"],
        ci95=MappingProxyType(ci),
        std=MappingProxyType(std),
        method=method,
        model=model,
        params=params.copy(),
        covariance=cov.copy(),
        noise_sigma=noise_sigma,
        n_samples=n,
        iterations=iterations,
        converged=converged,
        t_s=arrays[0],
        energy=arrays[1],
        energy_fit=arrays[2],
        residuals_ln_e=arrays[3],
        theta_rad=arrays[4],
    )


# ----------------------------------------------------------------------------------------------
# Estimators on prepared regressors (design matrices kept transposed, (4, n), for fast products)


def _lin(p: np.ndarray, xt: np.ndarray) -> np.ndarray:
    """p @ xt without BLAS (its gemv is slow for a 4 x n operand, and its threads spin on a busy
    machine)."""
    return np.einsum("i,in->n", p, xt)


def _gram(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a @ b.T for (4, n) operands, single-threaded."""
    return np.einsum("in,jn->ij", a, b)


def _scaled_inverse(normal: np.ndarray) -> np.ndarray:
    """Inverse of a 4x4 normal matrix after scaling it to unit diagonal (columns differ by 1e6)."""
    scale = np.sqrt(np.diag(normal))
    scale[scale == 0] = 1.0
    return np.linalg.inv(normal / np.outer(scale, scale)) / np.outer(scale, scale)


def _weighted_ls(xt: np.ndarray, y: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Weighted least squares by scaled normal equations; returns params, (X^T W X)^-1 and the
    weighted residual sum."""
    xw = xt * w
    inv = _scaled_inverse(_gram(xw, xt))
    p = inv @ (xw @ y)
    r = y - _lin(p, xt)
    return p, inv, float(np.dot(w * r, r))


def _fit_log_linear(reg: DecayRegressors) -> tuple[np.ndarray, np.ndarray, float]:
    """Weighted closed-form LS on ln E in two passes.  Pass 1 weights by the measured E
    (var(ln E) = 4 s^2/E); pass 2 by the fitted E (weights independent of the noise) and removes
    the noise floor of the log, E[ln E_meas] = ln E + 2 s^2/E, which matters late in a long decay."""
    xt = reg.xt
    e_ref = float(np.max(reg.energy))
    dof = max(reg.ln_e.size - len(PARAM_NAMES), 1)
    p, _, rss = _weighted_ls(xt, reg.ln_e, reg.energy / e_ref)
    sigma2 = rss / dof * e_ref / 4.0
    model = np.exp(_lin(p, xt))
    p, inv, rss = _weighted_ls(xt, reg.ln_e - 2.0 * sigma2 / model, model / e_ref)
    s2 = rss / dof  # estimates 4 sigma^2 / e_ref
    return p, s2 * inv, math.sqrt(s2 * e_ref / 4.0)


def _gauss_newton_step(xt: np.ndarray, energy: np.ndarray, p: np.ndarray, weighted: bool):
    """One Gauss-Newton increment on the residual E - E_model: (dp, J^T W J, chi2 per dof)."""
    model = np.exp(_lin(p, xt))
    r = energy - model
    jt = xt * model  # (d E_model / d params)^T
    jw = jt / model if weighted else jt  # = xt when weighted (W = 1/E_model)
    normal = _gram(jw, jt)
    dp = _scaled_inverse(normal) @ (jw @ r)
    chi2 = float(np.dot(r, r / model if weighted else r)) / max(energy.size - len(PARAM_NAMES), 1)
    return dp, normal, chi2


def _gn_covariance(xt: np.ndarray, energy: np.ndarray, p: np.ndarray, weighted: bool) -> tuple[np.ndarray, float]:
    """Covariance of a Gauss-Newton fit with var(E_i) = c E_i (sandwich form when unweighted)."""
    model = np.exp(_lin(p, xt))
    r = energy - model
    jt = xt * model
    c = float(np.dot(r, r / model)) / max(energy.size - len(PARAM_NAMES), 1)  # estimates 4 sigma^2
    if weighted:
        cov = c * _scaled_inverse(_gram(jt, xt))
    else:
        bread = _scaled_inverse(_gram(jt, jt))
        cov = bread @ _gram(jt * (c * model), jt) @ bread
    return cov, math.sqrt(c / 4.0)


def _initial_decay(reg: DecayRegressors) -> np.ndarray:
    """(ln E0, gamma) from a weighted two-parameter log-linear fit; b_c = b_s = 0 (the patent's start)."""
    w = reg.energy / np.max(reg.energy)
    p2, _, _ = _weighted_ls(reg.xt[:2], reg.ln_e, w)
    return np.array([p2[0], p2[1], 0.0, 0.0])


def _gn_converged(dp: np.ndarray, normal: np.ndarray, chi2: float) -> bool:
    """The step moved the fit by under 1e-3 of its own standard error (normal / chi2 ~ information)."""
    return float(dp @ normal @ dp) <= 1e-6 * max(chi2, 1e-300)


def _fit_gauss_newton(
    reg: DecayRegressors, *, weighted: bool, start: str, max_iter: int = 30
) -> tuple[np.ndarray, np.ndarray, float, int, bool]:
    if start == "zero":
        p = _initial_decay(reg)
    elif start == "log-linear":
        p, _, _ = _fit_log_linear(reg)
    else:
        raise DampingFitError(f"start={start!r} is not 'zero' or 'log-linear'")
    converged = False
    it = 0
    energy = reg.energy
    floor_removed = False
    while it < max_iter:
        it += 1
        dp, normal, chi2 = _gauss_newton_step(reg.xt, energy, p, weighted)
        p = p + dp
        if not np.all(np.isfinite(p)):  # bounded iterations, and a named error for data it cannot fit
            raise DampingFitError(f"Gauss-Newton diverged at iteration {it} of {max_iter}: the data do not follow a "
                                  "free decay")
        if _gn_converged(dp, normal, chi2):
            if floor_removed:
                converged = True
                break
            # the measured E carries a noise floor 4 s^2: remove it and iterate once more
            _, noise = _gn_covariance(reg.xt, reg.energy, p, weighted)
            energy = reg.energy - 4.0 * noise * noise
            floor_removed = True
    cov, noise_sigma = _gn_covariance(reg.xt, energy, p, weighted)
    return p, cov, noise_sigma, it, converged


# ----------------------------------------------------------------------------------------------
# Public batch API


def fit_free_decay(
    t_s,
    cx,
    sx,
    cy,
    sy,
    *,
    method: str = "log-linear",
    model: str = "exact",
    start: str = "zero",
) -> DampingFit:
    """Fit a free decay for theta_tau, Delta(1/tau) and tau with honest 95 % intervals.

    method: "log-linear" (weighted closed form on ln E), "gauss-newton" (the patent's fit of E,
    weighted for var(E) = 4 s^2 E), "gauss-newton-unweighted" (the patent as printed).
    model: "exact" (quadrature-aware, default) or "patent" (cos 4 theta, k ~ 0).
    start: Gauss-Newton start, "zero" (the patent's D = 0, gamma and E0 from ln E) or "log-linear".
    """
    if method not in METHODS:
        raise DampingFitError(f"method={method!r} is not one of {METHODS}")
    reg = decay_regressors(t_s, cx, sx, cy, sy, model=model)
    if method == "log-linear":
        p, cov, noise = _fit_log_linear(reg)
        return _make_result(reg, t_s, p, cov, noise, method, model, 1, True)
    p, cov, noise, it, conv = _fit_gauss_newton(reg, weighted=(method == "gauss-newton"), start=start)
    return _make_result(reg, t_s, p, cov, noise, method, model, it, conv)


def fit_free_decay_q(t_s, q, **kwargs) -> DampingFit:
    """fit_free_decay on an (n, 4) array of slow variables (cx, sx, cy, sy)."""
    q = np.asarray(q, dtype=float)
    if q.ndim != 2 or q.shape[1] != 4:
        raise DampingFitError(f"q has shape {q.shape}; expected (n, 4) = cx, sx, cy, sy")
    return fit_free_decay(t_s, q[:, 0], q[:, 1], q[:, 2], q[:, 3], **kwargs)


# ----------------------------------------------------------------------------------------------
# Sequential form


class SequentialDampingFit:
    """The patent's identification as data arrive: each `update` appends a block of samples and
    returns the current estimate (its plot arrays empty; `result()` gives them in full).

    method "gauss-newton": `iterations_per_update` Gauss-Newton increments on the residuals stacked
    over the growing window (PHYSICS.md pitfall (a)), started from D = 0 with (ln E0, gamma) from
    the first block; each costs one pass over the data so far.
    method "log-linear": exact recursive least squares on ln E (running normal equations, O(block)
    per update); each block is weighted by the energy the estimate before it predicts.
    """

    def __init__(self, *, method: str = "gauss-newton", model: str = "exact", iterations_per_update: int = 1) -> None:
        if method not in ("gauss-newton", "log-linear"):
            raise DampingFitError(f"method={method!r} is not 'gauss-newton' or 'log-linear'")
        if model not in MODELS:
            raise DampingFitError(f"model={model!r} is not one of {MODELS}")
        if iterations_per_update < 1:
            raise DampingFitError(f"iterations_per_update={iterations_per_update!r} must be >= 1")
        self.method = method
        self.model = model
        self.iterations_per_update = int(iterations_per_update)
        self._n = 0
        self._cap = 0
        self._t = np.empty(0)
        self._e = np.empty(0)
        self._ln = np.empty(0)
        self._phi = np.empty(0)
        self._xt = np.empty((4, 0))
        self._last: tuple[float, float, float, float] | None = None  # t, wrapped phi, mc, ms
        self._p: np.ndarray | None = None
        self._normal = np.zeros((4, 4))
        self._rhs = np.zeros(4)
        self._yy = 0.0
        self._y0 = 0.0
        self._iterations = 0
        self._converged = False
        self._estimate: DampingFit | None = None

    @property
    def n_samples(self) -> int:
        return self._n

    def _grow(self, need: int) -> None:
        if need <= self._cap:
            return
        cap = max(need, 2 * self._cap, 4096)
        for name in ("_t", "_e", "_ln", "_phi"):
            new = np.empty(cap)
            new[: self._n] = getattr(self, name)[: self._n]
            setattr(self, name, new)
        xt = np.empty((4, cap))
        xt[:, : self._n] = self._xt[:, : self._n]
        self._xt = xt
        self._cap = cap

    def update(self, t_s, cx, sx, cy, sy) -> DampingFit | None:
        """Append a block of samples; return the current estimate (None until enough samples)."""
        t, cx, sx, cy, sy = _as_channels(t_s, cx, sx, cy, sy, min_samples=0)
        m = t.size
        if m == 0:
            return self._estimate
        if self._last is not None and t[0] <= self._last[0]:
            raise DampingFitError(f"block starts at t={t[0]!r} s, not after the previous sample at {self._last[0]!r} s")
        energy, phi, mc, ms = _sample_parts(cx, sx, cy, sy, self.model)
        self._grow(self._n + m)
        n0 = self._n
        sl = slice(n0, n0 + m)
        if self._last is None:
            t_all, phi_all, mc_all, ms_all = t, phi, mc, ms
            base = np.array([phi[0], 0.0, 0.0])
            self._t0_s = float(t[0])
            self._y0 = float(np.log(energy[0]))
        else:
            tp, php, mcp, msp = self._last
            t_all = np.concatenate([[tp], t])
            phi_all = np.concatenate([[php], phi])
            mc_all = np.concatenate([[mcp], mc])
            ms_all = np.concatenate([[msp], ms])
            base = np.array([self._phi[n0 - 1], -self._xt[2, n0 - 1], -self._xt[3, n0 - 1]])
        d, dc, ds = _step_integrals(np.diff(t_all), phi_all, mc_all, ms_all)
        first = 1 if self._last is None else 0  # the very first sample starts every integral at 0
        k = slice(n0 + first, n0 + m)
        self._phi[n0] = base[0]
        self._phi[k] = base[0] + np.cumsum(d)
        self._xt[0, sl] = 1.0
        self._xt[1, sl] = self._t0_s - t
        self._xt[2:, n0] = -base[1:]
        self._xt[2, k] = -(base[1] + np.cumsum(dc))
        self._xt[3, k] = -(base[2] + np.cumsum(ds))
        self._t[sl] = t
        self._e[sl] = energy
        self._ln[sl] = np.log(energy)
        self._last = (float(t[-1]), float(phi[-1]), float(mc[-1]), float(ms[-1]))
        self._n += m
        if self.method == "log-linear":
            xb = self._xt[:, sl]
            w = np.exp(_lin(self._p, xb)) if self._p is not None else energy  # predicted E: independent of this noise
            y = self._ln[sl] - self._y0
            if self._p is not None:  # remove the noise floor of the log, 2 s^2 / E (see _fit_log_linear)
                y = y - 0.5 * self._c_hat / w
            xw = xb * w
            self._normal += _gram(xw, xb)
            self._rhs += xw @ y
            self._yy += float(np.dot(w * y, y))
        if self._n < _MIN_SAMPLES:
            return self._estimate
        self._estimate = self._solve(curves=False)
        return self._estimate

    def result(self) -> DampingFit | None:
        """The current estimate with its plot arrays (energy, fit, residuals, theta) over all data."""
        if self._n < _MIN_SAMPLES or self._p is None:
            return None
        return self._finish(curves=True)

    def _regressors(self) -> DecayRegressors:
        n = self._n
        return DecayRegressors(t_rel_s=-self._xt[1, :n], energy=self._e[:n], ln_e=self._ln[:n],
                               phi_rad=self._phi[:n], xt=self._xt[:, :n])

    def _solve(self, *, curves: bool) -> DampingFit:
        reg = self._regressors()
        if self.method == "log-linear":
            scale = np.sqrt(np.diag(self._normal))
            scale[scale == 0] = 1.0
            normal_s = self._normal / np.outer(scale, scale)
            if np.linalg.cond(normal_s) > 1e12:  # too little data to see the modulation yet
                p = _initial_decay(reg)
                p[0] -= self._y0
            else:
                p = np.linalg.solve(normal_s, self._rhs / scale) / scale
            rss = max(self._yy - 2.0 * float(p @ self._rhs) + float(p @ self._normal @ p), 0.0)
            p[0] += self._y0
            self._p = p
            self._c_hat = rss / max(self._n - 4, 1)  # estimates 4 sigma^2
            self._iterations += 1
            self._converged = True
        else:
            if self._p is None:
                self._p = _initial_decay(reg)
            for _ in range(self.iterations_per_update):
                dp, normal, chi2 = _gauss_newton_step(reg.xt, reg.energy, self._p, True)
                self._p = self._p + dp
                self._iterations += 1
                self._converged = _gn_converged(dp, normal, chi2)
            self._c_hat = chi2  # 4 sigma^2; with the step's normal matrix this gives the covariance
            self._gn_cov = chi2 * _scaled_inverse(normal)
        return self._finish(curves=curves)

    def _finish(self, *, curves: bool) -> DampingFit:
        reg = self._regressors()
        if self.method == "log-linear":
            try:
                cov = self._c_hat * np.linalg.inv(self._normal)
            except np.linalg.LinAlgError:
                cov = np.full((4, 4), np.inf)
            noise = math.sqrt(self._c_hat / 4.0)
        elif curves:
            cov, noise = _gn_covariance(reg.xt, reg.energy, self._p, True)
        else:
            cov, noise = self._gn_cov, math.sqrt(self._c_hat / 4.0)
        return _make_result(reg, self._t[: self._n], self._p, cov, noise, "sequential " + self.method, self.model,
                            self._iterations, self._converged, curves=curves)


# ----------------------------------------------------------------------------------------------
# Compensation verification


@dataclass(frozen=True)
class AngleDriftFit:
    """The 4-theta harmonic of a measured drift: rate = offset + amplitude sin 4(theta - phase).

    Unpacks as (amplitude_rad_s, phase_rad).  For damping, phase is the most damped axis."""

    amplitude_rad_s: float
    phase_rad: float
    offset_rad_s: float
    amplitude_ci95: tuple[float, float]
    residual_rms_rad_s: float
    n_samples: int

    def __iter__(self):
        return iter((self.amplitude_rad_s, self.phase_rad))

    def amplitude_dph(self, bryan_factor: float = 1.0) -> float:
        """Amplitude in deg/h, divided by the Bryan factor when the rate is the wave's own."""
        if not bryan_factor > 0:
            raise ValueError(f"bryan_factor={bryan_factor!r} must be > 0")
        return math.degrees(self.amplitude_rad_s / bryan_factor) * 3600.0


def fit_angle_drift(theta_rad, rate_rad_s) -> AngleDriftFit:
    """Least-squares fit of offset + A cos 4 theta + B sin 4 theta to a drift rate against the wave
    angle, for the drift before and after compensation."""
    th = np.asarray(theta_rad, dtype=float).reshape(-1)
    rate = np.asarray(rate_rad_s, dtype=float).reshape(-1)
    if th.size != rate.size:
        raise ValueError(f"theta_rad has {th.size} samples but rate_rad_s has {rate.size}")
    if th.size < 4:
        raise ValueError(f"fit_angle_drift needs at least 4 samples, got {th.size}")
    if not (np.all(np.isfinite(th)) and np.all(np.isfinite(rate))):
        raise ValueError("theta_rad and rate_rad_s must be finite")
    x = np.column_stack([np.ones_like(th), np.cos(4 * th), np.sin(4 * th)])
    p, *_ = np.linalg.lstsq(x, rate, rcond=None)
    r = rate - x @ p
    dof = max(th.size - 3, 1)
    s2 = float(r @ r) / dof
    cov = s2 * np.linalg.pinv(x.T @ x)
    a, b = float(p[1]), float(p[2])
    amp = math.hypot(a, b)
    # A cos + B sin = amp sin(4 th + psi), psi = atan2(A, B)  ->  phase = -psi / 4
    phase = (-0.25 * math.atan2(a, b)) % (math.pi / 2)
    if amp > 0:
        g = np.array([0.0, a / amp, b / amp])
        sd = math.sqrt(max(float(g @ cov @ g), 0.0))
    else:
        sd = math.sqrt(max(0.5 * (cov[1, 1] + cov[2, 2]), 0.0))
    k = float(_special().stdtrit(dof, 0.975))
    return AngleDriftFit(
        amplitude_rad_s=amp,
        phase_rad=phase,
        offset_rad_s=float(p[0]),
        amplitude_ci95=(max(0.0, amp - k * sd), amp + k * sd),
        residual_rms_rad_s=math.sqrt(s2),
        n_samples=int(th.size),
    )


@dataclass(frozen=True)
class DriftHarmonic:
    """One harmonic m of a drift against the wave angle: amplitude sin m(theta - phase); phase_ci95:
    the phase's 95 % interval (rad; the whole period 2 pi / m when the amplitude's interval holds 0)."""

    order: int
    amplitude: float
    phase_rad: float
    ci95: tuple[float, float]
    phase_ci95: tuple[float, float] | None = None


@dataclass(frozen=True)
class DriftHarmonics:
    """A drift against the wave angle in full: its mean, each harmonic fitted (with 95 % intervals)
    and the rms of what is left.  Units are those of the rate given (rad/s, deg/h...)."""

    mean: float
    mean_ci95: tuple[float, float]
    harmonics: Mapping[int, DriftHarmonic]
    rest_rms: float
    n_samples: int

    def scaled(self, factor: float) -> DriftHarmonics:
        """The same fit in other units (factor > 0, e.g. rad/s -> output-referred deg/h)."""
        if not factor > 0:
            raise ValueError(f"factor={factor!r} must be > 0")
        hs = {m: DriftHarmonic(m, h.amplitude * factor, h.phase_rad, (h.ci95[0] * factor, h.ci95[1] * factor),
                               h.phase_ci95) for m, h in self.harmonics.items()}
        lo, hi = self.mean_ci95
        return DriftHarmonics(self.mean * factor, (lo * factor, hi * factor), hs, self.rest_rms * factor,
                              self.n_samples)


def fit_drift_harmonics(theta_rad, rate, orders: tuple[int, ...] = (4, 8, 12)) -> DriftHarmonics:
    """Least-squares fit of mean + sum_m (A_m cos m theta + B_m sin m theta) to a drift rate against
    the wave angle: the damping drift is the 4 theta term, a loop or split defect shows in the mean
    and the other harmonics.  Intervals (95 %): the mean's from Student t on the residual scatter;
    an amplitude's from the joint confidence ellipse of its (A, B) (radius^2 = 2 F(2, dof)), i.e.
    the distances of its nearest and farthest points from 0, so the interval holds 0 exactly when
    (0, 0) is a plausible (A, B) (a Rayleigh-biased amplitude alone would exclude 0 15 % of the
    time for an absent term).  The record should cover a whole period of the lowest order."""
    th = np.asarray(theta_rad, dtype=float).reshape(-1)
    y = np.asarray(rate, dtype=float).reshape(-1)
    n_par = 1 + 2 * len(orders)
    if th.size != y.size:
        raise ValueError(f"theta_rad has {th.size} samples but rate has {y.size}")
    if th.size <= n_par:
        raise ValueError(f"fit_drift_harmonics needs more than {n_par} samples for orders {orders}, got {th.size}")
    if not (np.all(np.isfinite(th)) and np.all(np.isfinite(y))):
        raise ValueError("theta_rad and rate must be finite")
    cols = [np.ones_like(th)]
    for m in orders:
        cols += [np.cos(m * th), np.sin(m * th)]
    x = np.column_stack(cols)
    p, *_ = np.linalg.lstsq(x, y, rcond=None)
    r = y - x @ p
    dof = th.size - n_par
    s2 = float(r @ r) / dof
    cov = s2 * np.linalg.pinv(x.T @ x)
    hs = _harmonics(p, cov, dof, orders, first=1)
    t = float(_special().stdtrit(dof, 0.975))
    half = t * math.sqrt(max(float(cov[0, 0]), 0.0))
    return DriftHarmonics(float(p[0]), (float(p[0]) - half, float(p[0]) + half), hs, math.sqrt(float(r @ r) / th.size),
                          int(th.size))


def _harmonics(p: np.ndarray, cov: np.ndarray, dof: int, orders: tuple[int, ...],
               first: int) -> dict[int, DriftHarmonic]:
    """Each harmonic's amplitude and phase with their 95 % intervals from a linear fit's (A_m, B_m)
    pairs (columns first, first + 1, ... of p and cov, in the order of `orders`): the amplitude's
    from the joint confidence ellipse, the phase's from the angle it subtends (fit_drift_harmonics)."""
    t = float(_special().stdtrit(dof, 0.975))
    radius = math.sqrt(2.0 * float(_special().fdtri(2, dof, 0.95)))
    hs = {}
    for i, m in enumerate(orders):
        j = first + 2 * i
        ab = p[j : j + 2]
        a, b = float(ab[0]), float(ab[1])
        amp = math.hypot(a, b)
        c = cov[j : j + 2, j : j + 2]
        reach = radius * math.sqrt(max(float(np.linalg.eigvalsh(c)[-1]), 0.0))  # farthest ellipse point from (A, B)
        try:
            holds_zero = float(ab @ np.linalg.solve(c, ab)) <= radius * radius
        except np.linalg.LinAlgError:
            holds_zero = amp <= reach
        lo = 0.0 if holds_zero else max(0.0, amp - reach)
        # A cos + B sin = amp sin(m th + psi), psi = atan2(A, B)  ->  phase = -psi / m
        phase = (-math.atan2(a, b) / m) % (2 * math.pi / m)
        # the phase's interval: the angle the confidence ellipse subtends seen from 0 (delta method:
        # d psi = (B dA - A dB) / amp^2), Student t; the whole period when the ellipse holds 0
        g = np.array([b, -a]) / max(amp * amp, 1e-300)
        half = t * math.sqrt(max(float(g @ c @ g), 0.0)) / m
        period = 2 * math.pi / m
        p_ci = (phase - period / 2, phase + period / 2) if holds_zero or half >= period / 2 else (phase - half,
                                                                                                phase + half)
        hs[m] = DriftHarmonic(m, amp, phase, (lo, amp + reach), p_ci)
    return hs


@dataclass(frozen=True)
class AngleHarmonicsFit:
    """fit_angle_harmonics' result: the drift (rad/s of wave angle), the orders fitted, the rms of
    the angle the fit leaves (rad) and the (A_m, B_m) coefficients in order of the orders."""

    drift: DriftHarmonics
    orders: tuple[int, ...]
    angle_rest_rms_rad: float
    coef: np.ndarray = field(repr=False)

    def drift_rad_s(self, theta_rad: np.ndarray) -> np.ndarray:
        """The fitted drift at wave angles theta (rad/s of wave angle)."""
        th = np.asarray(theta_rad, dtype=float)
        out = np.full_like(th, self.drift.mean)
        for i, m in enumerate(self.orders):
            out = out + self.coef[2 * i] * np.cos(m * th) + self.coef[2 * i + 1] * np.sin(m * th)
        return out


def fit_angle_harmonics(t_s, theta_rad, command_rad_s: float,
                        orders: tuple[int, ...] = (4, 8, 12)) -> AngleHarmonicsFit:
    """The drift read from the wave-angle record itself: theta(t) - command t = c + mean t +
    sum_m (A_m I_cos,m(t) + B_m I_sin,m(t)), I_cos,m(t) = integral_0^t cos m theta dt (and sin):
    a linear least-squares fit of the angle (its pickoff noise is white; block slopes differentiate
    it and lose the precision).  The drift is mean + sum_m (A_m cos m theta + B_m sin m theta) rad/s
    of wave angle; intervals as fit_drift_harmonics, from the angle fit's covariance (Student t on
    the residual scatter).  drift.rest_rms: NaN here; angle_rest_rms_rad the angle left."""
    t = np.asarray(t_s, dtype=float).reshape(-1)
    th = np.unwrap(4.0 * np.asarray(theta_rad, dtype=float).reshape(-1)) / 4.0
    n_par = 2 + 2 * len(orders)
    if t.size != th.size:
        raise ValueError(f"t_s has {t.size} samples but theta_rad has {th.size}")
    if t.size <= n_par:
        raise ValueError(f"fit_angle_harmonics needs more than {n_par} samples for orders {orders}, got {t.size}")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(th))):
        raise ValueError("t_s and theta_rad must be finite")
    tr = t - t[0]
    cols = [np.ones_like(tr), tr]
    for m in orders:
        for f in (np.cos, np.sin):
            g = f(m * th)
            cols.append(np.concatenate([[0.0], np.cumsum(0.5 * (g[1:] + g[:-1]) * np.diff(tr))]))
    x = np.column_stack(cols)
    y = th - th[0] - float(command_rad_s) * tr
    scale = np.maximum(np.max(np.abs(x), axis=0), 1e-300)  # a column of ones beside columns of seconds
    xs = x / scale
    ps, *_ = np.linalg.lstsq(xs, y, rcond=None)
    p = ps / scale
    r = y - xs @ ps
    dof = t.size - n_par
    s2 = float(r @ r) / dof
    cov = s2 * np.linalg.pinv(xs.T @ xs) / np.outer(scale, scale)
    hs = _harmonics(p, cov, dof, orders, first=2)
    k = float(_special().stdtrit(dof, 0.975))
    half = k * math.sqrt(max(float(cov[1, 1]), 0.0))
    drift = DriftHarmonics(float(p[1]), (float(p[1]) - half, float(p[1]) + half), hs, math.nan, int(t.size))
    return AngleHarmonicsFit(drift, tuple(orders), math.sqrt(float(r @ r) / t.size), np.asarray(p[2:], dtype=float))
