"""A joint (four-channel) damping estimator: output-error fit of the whole linear slow model.

q(t) = expm(A(z) t) q0 with z = (gamma, nu, b_c, b_s, c_m, n, h_c, h_s) and q0 unknown (12
parameters), fitted to cx, sx, cy, sy by Gauss-Newton (maximum likelihood under white noise, the
estimator the four-channel Cramer-Rao bound of `damping_design` refers to).  Unlike the energy
fits it uses the wobble of the wave angle too, so it can be ~1.4x tighter; unlike them it is also
moved by anything that turns the wave outside the model (table-rate ripple, loop forces).
To keep it fast the samples are averaged in bins and the model is averaged the same way, exactly
(the bin mean of expm steps is one matrix), so binning loses no information the model can use.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np
from scipy import special  # stdtrit: Student t quantiles without importing scipy.stats (~1 s)
from scipy.linalg import expm

from .damping import DampingFitError, fit_free_decay
from .slow_model import linear_matrix, orbit_elements

JOINT_NAMES = ("q1_0", "p1_0", "q2_0", "p2_0", "gamma", "nu", "b_c", "b_s", "c_m", "n", "h_c", "h_s")
_NP = len(JOINT_NAMES)


@dataclass(frozen=True)
class JointDampingFit:
    """Result of the four-channel fit: the same three quantities and intervals as DampingFit, plus
    every model coefficient (`params` over JOINT_NAMES, SI units) and its covariance."""

    theta_tau_deg: float
    delta_inv_tau_per_s: float
    tau_s: float
    ci95: Mapping[str, tuple[float, float]]
    std: Mapping[str, float]
    params: np.ndarray
    covariance: np.ndarray
    noise_sigma: float
    n_samples: int
    bin_samples: int
    iterations: int
    converged: bool


def _propagate(phi: np.ndarray, x0: np.ndarray, n: int, block: int = 256) -> np.ndarray:
    """x_k = phi^k x0 for k = 0..n-1, by powers of phi in blocks."""
    b = min(block, n)
    powers = np.empty((b,) + phi.shape)
    powers[0] = np.eye(phi.shape[0])
    for k in range(1, b):
        powers[k] = powers[k - 1] @ phi
    step = powers[b - 1] @ phi  # phi^b
    out = np.empty((n, x0.size))
    x = x0
    for start in range(0, n, b):
        take = min(b, n - start)
        out[start : start + take] = powers[:take] @ x
        x = step @ x
    return out


def _model_and_jacobian(z: np.ndarray, dt: float, m: int, n_bins: int) -> tuple[np.ndarray, np.ndarray]:
    """Bin means of q and of dq/dparams for parameters z (JOINT_NAMES order): (n_bins, 4), (n_bins, 4, 12)."""
    zg = z[4:]
    a = linear_matrix(zg)
    size = 4 * (_NP + 1)
    big = np.zeros((size, size))
    for b in range(_NP + 1):
        big[4 * b : 4 * b + 4, 4 * b : 4 * b + 4] = a
    for j in range(4, _NP):
        unit = np.zeros(8)
        unit[j - 4] = 1.0
        big[4 * (j + 1) : 4 * (j + 2), 0:4] = linear_matrix(unit)
    x0 = np.zeros(size)
    x0[:4] = z[:4]
    for j in range(4):
        x0[4 * (j + 1) + j] = 1.0
    phi1 = expm(big * dt)
    mean = np.zeros_like(phi1)
    p = np.eye(size)
    for _ in range(m):  # bin mean of the m samples that start at the bin's first sample
        mean += p
        p = p @ phi1
    mean /= m
    starts = _propagate(p, x0, n_bins)  # p = phi1^m after the loop
    y = starts @ mean.T
    return y[:, :4], y[:, 4:].reshape(n_bins, _NP, 4).transpose(0, 2, 1)


def _start(t: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Starting point: the energy fit's (gamma, b_c, b_s), nu from the wave angle's mean turn, c_m
    from the temporal phase's, the first sample as q0, n = h_c = h_s = 0."""
    e = fit_free_decay(t, *q.T)
    el = orbit_elements(q)
    theta = np.unwrap(4.0 * el["theta_rad"]) / 4.0
    nu = -4.0 * np.polyfit(t - t[0], theta, 1)[0]
    c2, s2 = np.cos(2 * el["theta_rad"]), np.sin(2 * el["theta_rad"])
    chi = np.unwrap(2.0 * np.arctan2(-(q[:, 1] * c2 + q[:, 3] * s2), q[:, 0] * c2 + q[:, 2] * s2)) / 2.0
    c_m = 2.0 * np.polyfit(t - t[0], chi, 1)[0]
    z = np.zeros(_NP)
    z[:4] = q[0]
    z[4], z[5], z[6], z[7], z[8] = e.gamma_per_s, nu, e.b_c_per_s, e.b_s_per_s, c_m
    return z


def fit_joint_decay(t_s, cx, sx, cy, sy, *, bin_samples: int = 10, max_iter: int = 30) -> JointDampingFit:
    """Output-error fit of the linear slow model to all four channels (uniformly sampled data)."""
    t = np.asarray(t_s, dtype=float).reshape(-1)
    q = np.column_stack([np.asarray(c, dtype=float).reshape(-1) for c in (cx, sx, cy, sy)])
    if q.shape[0] != t.size:
        raise DampingFitError(f"channels have {q.shape[0]} samples but t_s has {t.size}")
    if bin_samples < 1:
        raise DampingFitError(f"bin_samples={bin_samples!r} must be >= 1")
    dts = np.diff(t)
    dt = float(np.median(dts))
    if t.size < 20 * bin_samples or not np.all(np.abs(dts - dt) <= 1e-6 * dt):
        raise DampingFitError("the joint fit needs uniformly sampled data, at least 20 bins")
    m = int(bin_samples)
    n_bins = t.size // m
    qb = q[: n_bins * m].reshape(n_bins, m, 4).mean(axis=1)
    z = _start(t, q)
    lam = 1e-3
    cost = math.inf
    converged = False
    it = 0
    jac = None
    for it in range(1, max_iter + 1):  # noqa: B007 - reported
        model, jac = _model_and_jacobian(z, dt, m, n_bins)
        r = qb - model
        cost = float(np.sum(r * r))
        jj = np.einsum("kci,kcj->ij", jac, jac)
        g = np.einsum("kci,kc->i", jac, r)
        scale = np.sqrt(np.diag(jj))
        scale[scale == 0] = 1.0
        jn = jj / np.outer(scale, scale)
        while True:  # Levenberg-Marquardt: accept a step only when it lowers the cost
            dz = np.linalg.solve(jn + lam * np.eye(_NP), g / scale) / scale
            new_model, _ = _model_and_jacobian(z + dz, dt, m, n_bins)
            new_cost = float(np.sum((qb - new_model) ** 2))
            if new_cost <= cost or lam > 1e6:
                break
            lam *= 10.0
        z = z + dz
        lam = max(lam / 10.0, 1e-9)
        if abs(cost - new_cost) <= 1e-9 * cost:
            converged = True
            break
    model, jac = _model_and_jacobian(z, dt, m, n_bins)
    r = qb - model
    dof = max(4 * n_bins - _NP, 1)
    s2_bin = float(np.sum(r * r)) / dof
    jj = np.einsum("kci,kcj->ij", jac, jac)
    cov = s2_bin * np.linalg.inv(jj)
    gamma, b_c, b_s = z[4], z[6], z[7]
    d = math.hypot(b_c, b_s)
    cb = cov[6:8, 6:8]
    g_d = np.array([b_c, b_s]) / d if d > 0 else np.zeros(2)
    g_th = np.array([-b_s, b_c]) * (0.25 / d**2) * (180 / math.pi) if d > 0 else np.zeros(2)
    std = {
        "theta_tau_deg": math.sqrt(max(float(g_th @ cb @ g_th), 0.0)),
        "delta_inv_tau_per_s": math.sqrt(max(float(g_d @ cb @ g_d), 0.0)),
        "tau_s": 2.0 / gamma**2 * math.sqrt(max(float(cov[4, 4]), 0.0)),
    }
    theta = math.degrees(0.25 * math.atan2(b_s, b_c)) % 90.0
    tau = 2.0 / gamma
    k = float(special.stdtrit(dof, 0.975))
    value = {"theta_tau_deg": theta, "delta_inv_tau_per_s": d, "tau_s": tau}
    ci = {name: (v - k * std[name], v + k * std[name]) for name, v in value.items()}
    ci["delta_inv_tau_per_s"] = (max(0.0, ci["delta_inv_tau_per_s"][0]), ci["delta_inv_tau_per_s"][1])
    return JointDampingFit(
        theta_tau_deg=theta, delta_inv_tau_per_s=d, tau_s=tau, ci95=MappingProxyType(ci), std=MappingProxyType(std),
        params=z, covariance=cov, noise_sigma=math.sqrt(s2_bin * m), n_samples=int(t.size), bin_samples=m,
        iterations=it, converged=converged,
    )
