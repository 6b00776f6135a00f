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
from types import MappingProxyType

import numpy as np
from scipy import stats

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


@dataclass(frozen=True)
class DecayRegressors:
    """Per-sample quantities of a decay: time since start, energy, unwrapped 4 theta, and the
    cumulative damping integrals C, S of the chosen model."""

    t_rel_s: np.ndarray
    energy: np.ndarray
    phi_rad: np.ndarray  # 4 theta, unwrapped (rad)
    c_int_s: np.ndarray  # integral of rho cos 4 theta (s)
    s_int_s: np.ndarray  # integral of rho sin 4 theta (s)

    def design(self) -> np.ndarray:
        """X such that ln E = X @ (ln_e0, gamma, b_c, b_s)."""
        return np.column_stack([np.ones_like(self.t_rel_s), -self.t_rel_s, -self.c_int_s, -self.s_int_s])


def _as_channels(t_s, cx, sx, cy, sy) -> tuple[np.ndarray, ...]:
    arrays = [np.asarray(a, dtype=float).reshape(-1) for a in (t_s, cx, sx, cy, sy)]
    n = arrays[0].size
    for name, a in zip(("t_s", "cx", "sx", "cy", "sy"), arrays, strict=True):
        if a.size != n:
            raise DampingFitError(f"{name} has {a.size} samples but t_s has {n}; all five must match")
        if not np.all(np.isfinite(a)):
            raise DampingFitError(f"{name} contains non-finite values")
    if n < _MIN_SAMPLES:
        raise DampingFitError(f"decay has {n} samples; at least {_MIN_SAMPLES} are needed")
    if np.any(np.diff(arrays[0]) <= 0):
        raise DampingFitError("t_s must be strictly increasing")
    return tuple(arrays)


def _step_integrals(dt: np.ndarray, phi: np.ndarray, rho: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Exact integrals of rho cos phi and rho sin phi over each step, phi linear within the step and
    rho taken at the step's mean (it varies on the decay time scale only)."""
    dphi = np.diff(phi)
    mid = 0.5 * (phi[1:] + phi[:-1])
    half = 0.5 * dphi
    small = np.abs(half) < 1e-6
    sinc = np.sin(half) / np.where(small, 1.0, half)
    sinc[small] = 1.0 - half[small] ** 2 / 6.0
    scale = dt * 0.5 * (rho[1:] + rho[:-1]) * sinc
    return scale * np.cos(mid), scale * np.sin(mid)


def _phase_and_rho(cx, sx, cy, sy) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    energy = cx * cx + sx * sx + cy * cy + sy * sy
    r_inv = cx * cx + sx * sx - cy * cy - sy * sy
    s_inv = 2.0 * (cx * cy + sx * sy)
    if np.any(energy <= 0):
        raise DampingFitError("the energy E = cx^2+sx^2+cy^2+sy^2 is zero at some sample")
    phi = np.arctan2(s_inv, r_inv)
    rho = np.sqrt(r_inv * r_inv + s_inv * s_inv) / energy
    return energy, phi, rho


def decay_regressors(t_s, cx, sx, cy, sy, *, model: str = "exact") -> DecayRegressors:
    """Energy, unwrapped 4 theta and the cumulative damping integrals of a recorded decay."""
    if model not in MODELS:
        raise DampingFitError(f"model={model!r} is not one of {MODELS}")
    t, cx, sx, cy, sy = _as_channels(t_s, cx, sx, cy, sy)
    energy, phi, rho = _phase_and_rho(cx, sx, cy, sy)
    phi = np.unwrap(phi)
    if model == "patent":
        rho = np.ones_like(rho)
    dc, ds = _step_integrals(np.diff(t), phi, rho)
    zero = np.zeros(1)
    return DecayRegressors(
        t_rel_s=t - t[0],
        energy=energy,
        phi_rad=phi,
        c_int_s=np.concatenate([zero, np.cumsum(dc)]),
        s_int_s=np.concatenate([zero, np.cumsum(ds)]),
    )


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


def _physical(params: np.ndarray, cov: np.ndarray, dof: int) -> tuple[dict, dict, dict]:
    """(ln_e0, gamma, b_c, b_s) and their covariance -> theta_tau, D, tau with delta-method std."""
    gamma, b_c, b_s = (float(v) for v in params[1:])
    d = math.hypot(b_c, b_s)
    theta_deg = math.degrees(0.25 * math.atan2(b_s, b_c)) % 90.0
    if theta_deg >= 90.0:  # -0.0 % 90 rounding
        theta_deg = 0.0
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
    k = float(stats.t.ppf(0.975, max(dof, 1)))
    value = {"theta_tau_deg": theta_deg, "delta_inv_tau_per_s": d, "tau_s": tau}
    ci = {
        "theta_tau_deg": (theta_deg - k * std["theta_tau_deg"], theta_deg + k * std["theta_tau_deg"]),
        "delta_inv_tau_per_s": (max(0.0, d - k * std["delta_inv_tau_per_s"]), d + k * std["delta_inv_tau_per_s"]),
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
) -> DampingFit:
    n = reg.energy.size
    dof = n - len(PARAM_NAMES)
    value, std, ci = _physical(params, cov, dof)
    ln_fit = reg.design() @ params
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
        t_s=np.asarray(t_s, dtype=float).copy(),
        energy=reg.energy,
        energy_fit=np.exp(ln_fit),
        residuals_ln_e=np.log(reg.energy) - ln_fit,
        theta_rad=0.25 * reg.phi_rad,
    )


# ----------------------------------------------------------------------------------------------
# Estimators on prepared regressors


def _weighted_ls(x: np.ndarray, y: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Weighted least squares by column-scaled normal equations (4 columns, well conditioned once
    scaled); returns params, (X^T W X)^-1 and the weighted residual sum."""
    xw = x * w[:, None]
    normal = xw.T @ x
    scale = np.sqrt(np.diag(normal))
    scale[scale == 0] = 1.0
    inv_s = np.linalg.inv(normal / np.outer(scale, scale))
    p = (inv_s @ ((xw.T @ y) / scale)) / scale
    r = y - x @ p
    return p, inv_s / np.outer(scale, scale), float(np.dot(w * r, r))


def _fit_log_linear(reg: DecayRegressors, *, passes: int = 2) -> tuple[np.ndarray, np.ndarray, float]:
    """Weighted closed-form LS on ln E: weights E (var(ln E) = 4 s^2/E), first from the measured E,
    then from the fitted E so that the weights do not correlate with the noise."""
    x = reg.design()
    y = np.log(reg.energy)
    w = reg.energy / np.max(reg.energy)
    p = inv = None
    rss = 0.0
    for _ in range(max(1, passes)):
        p, inv, rss = _weighted_ls(x, y, w)
        w = np.exp(x @ p - np.max(x @ p))
    dof = max(y.size - len(PARAM_NAMES), 1)
    s2 = rss / dof  # estimates 4 sigma^2 / max(E)
    e_ref = float(np.exp(np.max(x @ p)))
    noise_sigma = math.sqrt(s2 * e_ref / 4.0)
    return p, s2 * inv, noise_sigma


def _gauss_newton_step(
    x: np.ndarray, energy: np.ndarray, p: np.ndarray, weighted: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One Gauss-Newton increment on the residual E - E_model; returns (dp, J^T W J, model, w)."""
    model = np.exp(x @ p)
    r = energy - model
    jac = model[:, None] * x  # d E_model / d params
    w = 1.0 / model if weighted else np.ones_like(model)
    jw = jac * w[:, None]
    normal = jac.T @ jw
    scale = np.sqrt(np.diag(normal))
    scale[scale == 0] = 1.0
    dp = np.linalg.solve(normal / np.outer(scale, scale), (jw.T @ r) / scale) / scale
    return dp, normal, model, w


def _gn_covariance(x: np.ndarray, energy: np.ndarray, p: np.ndarray, weighted: bool) -> tuple[np.ndarray, float]:
    """Covariance of a Gauss-Newton fit with var(E_i) = c E_i (sandwich form when unweighted)."""
    model = np.exp(x @ p)
    r = energy - model
    jac = model[:, None] * x
    dof = max(energy.size - len(PARAM_NAMES), 1)
    c = float(np.sum(r * r / model)) / dof  # estimates 4 sigma^2
    if weighted:
        normal = jac.T @ (jac / model[:, None])
        cov = c * np.linalg.inv(normal)
    else:
        bread = np.linalg.inv(jac.T @ jac)
        meat = jac.T @ (jac * (c * model)[:, None])
        cov = bread @ meat @ bread
    return cov, math.sqrt(c / 4.0)


def _initial_decay(reg: DecayRegressors) -> np.ndarray:
    """(ln E0, gamma) from a weighted two-parameter log-linear fit; b_c = b_s = 0 (the patent's start)."""
    x = reg.design()[:, :2]
    y = np.log(reg.energy)
    w = reg.energy / np.max(reg.energy)
    p2, _, _ = _weighted_ls(x, y, w)
    return np.array([p2[0], p2[1], 0.0, 0.0])


def _fit_gauss_newton(
    reg: DecayRegressors, *, weighted: bool, start: str, max_iter: int = 30, rtol: float = 1e-10
) -> tuple[np.ndarray, np.ndarray, float, int, bool]:
    x = reg.design()
    if start == "zero":
        p = _initial_decay(reg)
    elif start == "log-linear":
        p, _, _ = _fit_log_linear(reg)
    else:
        raise DampingFitError(f"start={start!r} is not 'zero' or 'log-linear'")
    converged = False
    it = 0
    for it in range(1, max_iter + 1):  # noqa: B007 - the count is reported
        dp, normal, _, _ = _gauss_newton_step(x, reg.energy, p, weighted)
        p = p + dp
        # converged when the step is negligible against the parameter's own statistical scale
        if float(dp @ normal @ dp) <= rtol * max(float(p @ normal @ p), 1e-300):
            converged = True
            break
    cov, noise_sigma = _gn_covariance(x, reg.energy, p, weighted)
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
    returns the current estimate.

    method "gauss-newton": one (or `iterations_per_update`) Gauss-Newton increment on the residuals
    stacked over the growing window, started from D = 0 (PHYSICS.md pitfall (a)).
    method "log-linear": exact recursive least squares on ln E (running normal equations), the
    weights of each block predicted from the estimate before it.
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
        self._t: list[np.ndarray] = []
        self._e: list[np.ndarray] = []
        self._phi: list[np.ndarray] = []
        self._c: list[np.ndarray] = []
        self._s: list[np.ndarray] = []
        self._last: tuple[float, float, float, float, float] | None = None  # t, phi, rho, C, S
        self._p: np.ndarray | None = None
        self._normal = np.zeros((4, 4))
        self._rhs = np.zeros(4)
        self._n = 0
        self._iterations = 0
        self._estimate: DampingFit | None = None

    @property
    def n_samples(self) -> int:
        return self._n

    def result(self) -> DampingFit | None:
        return self._estimate

    def update(self, t_s, cx, sx, cy, sy) -> DampingFit | None:
        """Append a block of samples; return the current estimate (None until enough samples)."""
        arrays = [np.asarray(a, dtype=float).reshape(-1) for a in (t_s, cx, sx, cy, sy)]
        n = arrays[0].size
        if n == 0:
            return self._estimate
        for name, a in zip(("t_s", "cx", "sx", "cy", "sy"), arrays, strict=True):
            if a.size != n:
                raise DampingFitError(f"{name} has {a.size} samples but t_s has {n}; all five must match")
            if not np.all(np.isfinite(a)):
                raise DampingFitError(f"{name} contains non-finite values")
        t = arrays[0]
        if self._last is not None and t[0] <= self._last[0]:
            raise DampingFitError(f"block starts at t={t[0]!r} s, not after the previous sample at {self._last[0]!r} s")
        if np.any(np.diff(t) <= 0):
            raise DampingFitError("t_s must be strictly increasing")
        energy, phi, rho = _phase_and_rho(*arrays[1:])
        if self.model == "patent":
            rho = np.ones_like(rho)
        if self._last is None:
            phi = np.unwrap(phi)
            t_all, phi_all, rho_all = t, phi, rho
            c0 = s0 = 0.0
        else:
            t_prev, phi_prev, rho_prev, c0, s0 = self._last
            phi_all = np.unwrap(np.concatenate([[phi_prev], phi]))
            phi = phi_all[1:]
            t_all = np.concatenate([[t_prev], t])
            rho_all = np.concatenate([[rho_prev], rho])
        dc, ds = _step_integrals(np.diff(t_all), phi_all, rho_all)
        if self._last is None:
            c = np.concatenate([[0.0], np.cumsum(dc)])
            s = np.concatenate([[0.0], np.cumsum(ds)])
        else:
            c = c0 + np.cumsum(dc)
            s = s0 + np.cumsum(ds)
        self._last = (float(t[-1]), float(phi[-1]), float(rho[-1]), float(c[-1]), float(s[-1]))
        self._t.append(t)
        self._e.append(energy)
        self._phi.append(phi)
        self._c.append(c)
        self._s.append(s)
        self._n += n
        if self.method == "log-linear":
            self._accumulate(t, energy, c, s)
        if self._n < _MIN_SAMPLES:
            return self._estimate
        self._estimate = self._solve()
        return self._estimate

    def _regressors(self) -> DecayRegressors:
        t = np.concatenate(self._t)
        return DecayRegressors(
            t_rel_s=t - t[0],
            energy=np.concatenate(self._e),
            phi_rad=np.concatenate(self._phi),
            c_int_s=np.concatenate(self._c),
            s_int_s=np.concatenate(self._s),
        )

    def _t0(self) -> float:
        return float(self._t[0][0])

    def _accumulate(self, t, energy, c, s) -> None:
        x = np.column_stack([np.ones_like(t), -(t - self._t0()), -c, -s])
        if self._p is not None:
            w = np.exp(x @ self._p)  # predicted E: weights independent of this block's noise
        else:
            w = energy
        self._normal += x.T @ (x * w[:, None])
        self._rhs += x.T @ (w * np.log(energy))

    def _solve(self) -> DampingFit:
        reg = self._regressors()
        t_abs = np.concatenate(self._t)
        x = reg.design()
        if self.method == "log-linear":
            scale = np.sqrt(np.diag(self._normal))
            scale[scale == 0] = 1.0
            normal_s = self._normal / np.outer(scale, scale)
            if np.linalg.cond(normal_s) > 1e12:  # too little data to see the modulation yet
                p = _initial_decay(reg)
            else:
                p = np.linalg.solve(normal_s, self._rhs / scale) / scale
            self._p = p
            model = np.exp(x @ p)
            r = np.log(reg.energy) - x @ p
            dof = max(reg.energy.size - 4, 1)
            c_hat = float(np.sum(model * r * r)) / dof  # 4 sigma^2
            try:
                cov = c_hat * np.linalg.inv(self._normal)
            except np.linalg.LinAlgError:
                cov = np.full((4, 4), np.inf)
            self._iterations += 1
            return _make_result(reg, t_abs, p, cov, math.sqrt(c_hat / 4.0), "sequential log-linear", self.model,
                                self._iterations, True)
        if self._p is None:
            self._p = _initial_decay(reg)
        converged = False
        for _ in range(self.iterations_per_update):
            dp, normal, _, _ = _gauss_newton_step(x, reg.energy, self._p, True)
            self._p = self._p + dp
            self._iterations += 1
            converged = float(dp @ normal @ dp) <= 1e-10 * max(float(self._p @ normal @ self._p), 1e-300)
        cov, noise = _gn_covariance(x, reg.energy, self._p, True)
        return _make_result(reg, t_abs, self._p, cov, noise, "sequential gauss-newton", self.model,
                            self._iterations, converged)


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
    k = float(stats.t.ppf(0.975, dof))
    return AngleDriftFit(
        amplitude_rad_s=amp,
        phase_rad=phase,
        offset_rad_s=float(p[0]),
        amplitude_ci95=(max(0.0, amp - k * sd), amp + k * sd),
        residual_rms_rad_s=math.sqrt(s2),
        n_samples=int(th.size),
    )
