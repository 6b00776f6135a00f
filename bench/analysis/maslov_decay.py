"""Free-decay identification (Maslov et al. section 2): integrate 2 dq/dt = D(q) z over
[t_{i-1}, t_{i+1}] with Simpson's rule, y_i = q_{i+1} - q_{i-1} = (h/6)(D_{i-1} + 4 D_i + D_{i+1}) z
(the 1/2 of eq. 2.7 kept, eq. 2.8 drops it), stack the N-1 blocks, least squares; or the paper's
recursive least squares with 4x4 blocks (eq. 2.12), which gives the same answer.

Intervals.  The textbook interval (eq. 2.11) treats the 4(N-1) equation errors as independent,
but y_i and y_{i+2} share a sample, and the same noise enters the regressors: with white noise
e_j (std s per slow variable) on the samples, the error of block i at the true z is exactly
    r_i = (I - (h/3) J_{i+1}) e_{i+1} - (4h/3) J_i e_i - (I + (h/3) J_{i-1}) e_{i-1},
J_j = d(dq/dt)/dq at sample j (the model's Jacobian).  The differences telescope, so for slowly
varying regressors (gamma, nu) the textbook interval is tens of times too wide.  `ci95` uses the
exact sandwich of this linear map, Cov(z) = s^2 C (sum_j F_j^T F_j) C with C = (X^T X)^-1 and
F_j = X_{j-1} - X_{j+1} - (h/3) J_j^T (X_{j-1} + 4 X_j + X_{j+1}); s^2 is estimated from the
residual sum of squares divided by its expectation per unit noise variance, tr(L L^T) (n - k)/n.
Coverage measured by Monte Carlo in benchmarks/maslov_coverage.py and tests/test_maslov_decay.py.
"""

from __future__ import annotations

import math

import numpy as np

from bench.analysis.maslov_result import (
    Identification,
    check_finite_arrays,
    derived_quantities,
    intervals,
    t_quantile,
)
from bench.analysis.maslov_terms import check_model, free_param_names, nonlinear_columns, nonlinear_jacobian
from bench.analysis.slow_model import linear_matrix

# Dg(q)[a, c] = _DG_SIGN[a, c] * q[_DG_INDEX[a, c]] (slow_model.regressor_linear, by table lookup)
_DG_INDEX = np.array(
    [[0, 2, 0, 2, 1, 3, 1, 3], [1, 3, 1, 3, 0, 2, 0, 2], [2, 0, 2, 0, 3, 1, 3, 1], [3, 1, 3, 1, 2, 0, 2, 0]]
)
_DG_SIGN = np.array(
    [
        [-1, 1, -1, -1, 1, 1, 1, 1],
        [-1, 1, -1, -1, -1, -1, -1, -1],
        [-1, -1, 1, -1, 1, -1, -1, 1],
        [-1, -1, 1, -1, -1, 1, 1, -1],
    ],
    dtype=float,
)
#: B_m = dDg/dq_m, shape (4, 4, 8): Dg(q) = sum_m q_m B_m
_DG_BASIS = np.stack([_DG_SIGN * (_DG_INDEX == m) for m in range(4)])


def dg_fast(q: np.ndarray) -> np.ndarray:
    """Dg(q), shape (..., 4, 8), equal to slow_model.regressor_linear but by one gather."""
    return np.asarray(q, dtype=float)[..., _DG_INDEX] * _DG_SIGN


def simpson_states(q: np.ndarray, dt_s: float) -> np.ndarray:
    """(h/6)(q_{i-1} + 4 q_i + q_{i+1}), i = 1..N-1: Dg of these is the Simpson-integrated Dg block."""
    return (dt_s / 6.0) * (q[:-2] + 4.0 * q[1:-1] + q[2:])


def simpson_regressors(q: np.ndarray, dt_s: float, model: str) -> tuple[np.ndarray, np.ndarray]:
    """(X, y): X_i = (h/6)(D(q_{i-1}) + 4 D(q_i) + D(q_{i+1})) shape (N-1, 4, k), y_i = q_{i+1} - q_{i-1}.

    Dg is linear in q, so its Simpson sum is Dg of the Simpson-weighted states (one regressor
    evaluation instead of three)."""
    parts = [dg_fast(simpson_states(q, dt_s))]
    if model != "linear":
        nl = nonlinear_columns(q, model)
        parts.append((dt_s / 6.0) * (nl[:-2] + 4.0 * nl[1:-1] + nl[2:]))
    x = np.concatenate(parts, axis=-1) if len(parts) > 1 else parts[0]
    return x, q[2:] - q[:-2]


def _padded_neighbours(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For every sample j = 0..N: (X_{j-1}, X_j, X_{j+1}) with zeros outside blocks 1..N-1."""
    n_blocks = x.shape[0]
    xp = np.zeros((n_blocks + 4,) + x.shape[1:])
    xp[2 : n_blocks + 2] = x
    return xp[0 : n_blocks + 2], xp[1 : n_blocks + 3], xp[2 : n_blocks + 4]


def _error_map_norm(jac: np.ndarray, h3: float, n_blocks: int) -> float:
    """tr(L L^T) of the error map; jac is (4, 4) constant or (N+1, 4, 4) per sample."""
    eye = np.eye(4)
    if jac.ndim == 2:
        per_block = np.sum((eye - h3 * jac) ** 2) + np.sum((4 * h3 * jac) ** 2) + np.sum((eye + h3 * jac) ** 2)
        return n_blocks * float(per_block)
    after, here, before = jac[2:], jac[1:-1], jac[:-2]
    return float(np.sum((eye - h3 * after) ** 2) + np.sum((4 * h3 * here) ** 2) + np.sum((eye + h3 * before) ** 2))


def _linear_fit(q: np.ndarray, dt_s: float) -> dict[str, np.ndarray | float]:
    """Batch fit and sandwich of the linear model from 4x4 and 8x8 moments (no N x 4 x 8 array)."""
    qs = simpson_states(q, dt_s)
    y = q[2:] - q[:-2]
    xtx = np.einsum("mn,mak,nal->kl", qs.T @ qs, _DG_BASIS, _DG_BASIS)
    xty = np.einsum("ma,mak->k", qs.T @ y, _DG_BASIS)
    c = np.linalg.inv(xtx)
    z = np.linalg.solve(xtx, xty)
    a = linear_matrix(z)
    resid = y - qs @ (2.0 * a).T  # Dg(qs) z = 2 A qs
    h3 = dt_s / 3.0
    pad = np.zeros((2, 4))
    qp = np.vstack([pad, qs, pad])  # qp[j + 1] is Simpson state of block j
    qd = qp[0:-2] - qp[2:]
    qsum = qp[0:-2] + 4.0 * qp[1:-1] + qp[2:]
    w = np.hstack([qd, qsum])
    basis = np.concatenate([_DG_BASIS, -h3 * np.einsum("ba,mbk->mak", a, _DG_BASIS)])
    meat = np.einsum("ab,aik,bil->kl", w.T @ w, basis, basis)
    return {"z": z, "c": c, "resid": resid, "meat": meat, "lnorm": _error_map_norm(a, h3, qs.shape[0])}


_CHUNK = 8192  # samples per chunk: keeps the (chunk, 4, k) temporaries in cache


def _blocks(q: np.ndarray, dt_s: float, model: str, lo: int, hi: int) -> tuple[np.ndarray, np.ndarray]:
    """Simpson regressors and differences of the blocks with middle sample lo..hi-1 (1 <= lo)."""
    return simpson_regressors(q[lo - 1 : hi + 1], dt_s, model)


def _neighbour_blocks(q: np.ndarray, dt_s: float, model: str, s: int, e: int, k: int):
    """(X_{j-1}, X_j, X_{j+1}) for samples j = s..e-1, zero for blocks outside 1..N-1."""
    n_samples = q.shape[0]
    lo, hi = max(s - 1, 1), min(e + 1, n_samples - 1)
    xs = np.zeros((e - s + 2, 4, k))  # xs[m] holds block s - 1 + m
    xb, _ = _blocks(q, dt_s, model, lo, hi)
    xs[lo - (s - 1) : hi - (s - 1)] = xb
    return xs[:-2], xs[1:-1], xs[2:]


def _general_fit(q: np.ndarray, dt_s: float, model: str, recursive: bool, n_init: int | None) -> dict:
    """Fit from the Simpson regressors in chunks (nonlinear models) or materialised (recursive form)."""
    n_samples = q.shape[0]
    n_blocks = n_samples - 2
    k = 8 + len(nonlinear_columns(q[:1], model)[0, 0])
    if recursive:
        x, y = simpson_regressors(q, dt_s, model)
        m = n_init if n_init is not None else max(4 * k, n_blocks // 50)
        if not k <= m <= n_blocks:
            raise ValueError(f"n_init_blocks={m} must be between {k} and the {n_blocks} blocks")
        z, c = recursive_lsq(x, y, int(m))
    else:
        xtx, xty = np.zeros((k, k)), np.zeros(k)
        for lo in range(1, n_samples - 1, _CHUNK):
            x, y = _blocks(q, dt_s, model, lo, min(lo + _CHUNK, n_samples - 1))
            x2 = x.reshape(-1, k)
            xtx += x2.T @ x2
            xty += x2.T @ y.reshape(-1)
        c = np.linalg.inv(xtx)
        z = np.linalg.solve(xtx, xty)
    a = linear_matrix(z[:8])
    h3 = dt_s / 3.0
    resid = np.empty((n_blocks, 4))
    meat = np.zeros((k, k))
    jacs = []
    for s in range(0, n_samples, _CHUNK):
        e = min(s + _CHUNK, n_samples)
        x_prev, x_here, x_next = _neighbour_blocks(q, dt_s, model, s, e, k)
        lo, hi = max(s, 1), min(e, n_samples - 1)
        if hi > lo:
            yb = q[lo + 1 : hi + 1] - q[lo - 1 : hi - 1]
            resid[lo - 1 : hi - 1] = yb - x_here[lo - s : hi - s] @ z
        jac = a if model == "linear" else a + 0.5 * nonlinear_jacobian(q[s:e], model, z[8:])
        jacs.append(jac)
        simp = x_prev + 4.0 * x_here + x_next
        f = x_prev - x_next
        for b in range(4):  # f -= h3 J^T simp, per sample (a loop over 4 beats batched 4x4 matmul)
            jb = jac[b] if jac.ndim == 2 else jac[:, b]
            f -= h3 * jb[..., :, None] * simp[:, b, None, :]
        f2 = f.reshape(-1, k)
        meat += f2.T @ f2
    jac_all = a if model == "linear" else np.concatenate(jacs)
    return {"z": z, "c": c, "resid": resid, "meat": meat, "lnorm": _error_map_norm(jac_all, h3, n_blocks)}


def recursive_lsq(x: np.ndarray, y: np.ndarray, n_init_blocks: int) -> tuple[np.ndarray, np.ndarray]:
    """The paper's recursive least squares (eq. 2.12) with 4x4 blocks: batch start on the first
    n_init_blocks blocks, then for each block with regressor D (4 x k) and r = D^T:
        S = P r (I + r^T P r)^-1,  z += S (y - D z),  P -= S r^T P.
    Returns (z, P); P = (X^T X)^-1 of all blocks."""
    n_blocks, _, k = x.shape
    x0 = x[:n_init_blocks].reshape(-1, k)
    p = np.linalg.inv(x0.T @ x0)
    z = p @ (x0.T @ y[:n_init_blocks].reshape(-1))
    eye = np.eye(4)
    for i in range(n_init_blocks, n_blocks):
        d = x[i]
        pr = p @ d.T
        s = np.linalg.solve(eye + d @ pr, pr.T).T
        z = z + s @ (y[i] - d @ z)
        p = p - s @ pr.T
    return z, 0.5 * (p + p.T)


def identify_free_decay(
    t_s: np.ndarray,
    q1: np.ndarray,
    p1: np.ndarray,
    q2: np.ndarray,
    p2: np.ndarray,
    *,
    model: str = "linear",
    recursive: bool = False,
    natural_freq_hz: float | None = None,
    detuning_hz: float = 0.0,
    bryan_factor: float | None = None,
    n_init_blocks: int | None = None,
    level: float = 0.95,
) -> Identification:
    """Identify (gamma, nu, b_c, b_s, c_m, n, h_c, h_s[, xi[, kappa]]) from a free decay sampled
    uniformly.  detuning_hz: demodulation reference minus natural frequency (the fit sees
    c_m - 2 lam; c_m is reported with 2 lam added back).  natural_freq_hz enables Q, bryan_factor
    the zero-rate output in `derived`.  ci95 is the sandwich interval of the module docstring."""
    check_model(model)
    n = check_finite_arrays(t_s=t_s, q1=q1, p1=p1, q2=q2, p2=p2)
    names = free_param_names(model)
    k = len(names)
    if n < 3 or 4 * (n - 2) <= k:
        raise ValueError(f"{n} samples give {4 * max(n - 2, 0)} equations; need more than {k} for {model!r}")
    t = np.asarray(t_s, dtype=float)
    steps = np.diff(t)
    dt = float(np.mean(steps))
    if dt <= 0 or np.max(np.abs(steps - dt)) > 1e-6 * dt:
        raise ValueError(f"t_s must be uniformly increasing; steps range {steps.min():.6g}..{steps.max():.6g} s")
    if not 0 < level < 1:
        raise ValueError(f"level={level!r} must be in (0, 1)")
    q = np.stack([q1, p1, q2, p2], axis=-1).astype(float)
    if model == "linear" and not recursive:
        fit = _linear_fit(q, dt)
    else:
        fit = _general_fit(q, dt, model, recursive, n_init_blocks)
    z, c, resid = fit["z"], fit["c"], fit["resid"]
    ss = float(np.einsum("ia,ia->", resid, resid))
    n_eq = resid.size
    dof = n_eq - k
    sigma = math.sqrt(ss / dof)
    s_p = t_quantile(dof, level)
    se_text = sigma * np.sqrt(np.diag(c))
    noise_var = ss / (fit["lnorm"] * dof / n_eq)
    cov = noise_var * c @ fit["meat"] @ c
    se = np.sqrt(np.diag(cov))

    z_rep = z.copy()
    z_rep[4] += 2.0 * (2.0 * math.pi * detuning_hz)
    params = {nm: float(v) for nm, v in zip(names, z_rep, strict=True)}
    return Identification(
        model=model,
        method="free_decay_recursive" if recursive else "free_decay",
        params=params,
        sigma=sigma,
        ci95=intervals(names, z_rep, se, s_p),
        ci95_textbook=intervals(names, z_rep, se_text, s_p),
        sigma_params={nm: float(s) for nm, s in zip(names, se, strict=True)},
        derived=derived_quantities(params, natural_freq_hz=natural_freq_hz, bryan_factor=bryan_factor),
        residuals=resid,
        n_equations=n_eq,
        covariance=cov,
        noise_sigma=math.sqrt(noise_var),
        extras={"dt_s": dt, "level": level, "P": c},
    )
