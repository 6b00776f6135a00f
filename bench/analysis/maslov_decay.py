"""Free-decay identification (Maslov et al. section 2): integrate 2 dq/dt = D(q) z over
[t_{i-1}, t_{i+1}] with Simpson's rule, y_i = q_{i+1} - q_{i-1} = (h/6)(D_{i-1} + 4 D_i + D_{i+1}) z
(the 1/2 of eq. 2.7 kept, eq. 2.8 drops it), stack the N-1 blocks, least squares; or the paper's
recursive least squares with 4x4 blocks (eq. 2.12), which gives the same answer.  The recursion
runs over chunks of _RLS_CHUNK 4x4 blocks: one push-through update per chunk (square-root form)
equals that chunk's 4x4 updates applied in turn, so (z, P) after each chunk is the paper's state
after its last block; the states inside a chunk are not formed.  recursive_lsq(chunk_blocks=1) is
the literal one-block loop (tests compare the two).

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
from bench.analysis.maslov_terms import check_model, free_param_names, nonlinear_columns
from bench.analysis.slow_model import DG_BASIS, linear_matrix, regressor_linear


def simpson_states(q: np.ndarray, dt_s: float) -> np.ndarray:
    """(h/6)(q_{i-1} + 4 q_i + q_{i+1}), i = 1..N-1: Dg of these is the Simpson-integrated Dg block."""
    return (dt_s / 6.0) * (q[:-2] + 4.0 * q[1:-1] + q[2:])


def simpson_regressors(q: np.ndarray, dt_s: float, model: str) -> tuple[np.ndarray, np.ndarray]:
    """(X, y): X_i = (h/6)(D(q_{i-1}) + 4 D(q_i) + D(q_{i+1})) shape (N-1, 4, k), y_i = q_{i+1} - q_{i-1}.

    Dg is linear in q, so its Simpson sum is Dg of the Simpson-weighted states (one regressor
    evaluation instead of three)."""
    parts = [regressor_linear(simpson_states(q, dt_s))]
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
    xtx = np.einsum("mn,mak,nal->kl", qs.T @ qs, DG_BASIS, DG_BASIS)
    xty = np.einsum("ma,mak->k", qs.T @ y, DG_BASIS)
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
    basis = np.concatenate([DG_BASIS, -h3 * np.einsum("ba,mbk->mak", a, DG_BASIS)])
    meat = np.einsum("ab,aik,bil->kl", w.T @ w, basis, basis)
    return {"z": z, "c": c, "resid": resid, "meat": meat, "lnorm": _error_map_norm(a, h3, qs.shape[0])}


FREE_DECAY_METHODS = ("equation-error", "output-error")
_CHUNK = 8192  # samples per chunk: keeps the (chunk, 4, k) temporaries in cache
_RLS_CHUNK = 4096  # 4x4 blocks per chunk of the recursive form (its update equals their 4x4 updates in turn)

# the Jacobian of the nonlinear columns is  sum_c z_c dN_c/dq = alpha DS1 + beta DS2 + s1 u^T + s2 w^T
# with s1 = DS1 q, s2 = DS2 q (maslov_terms); these are DS1^T, DS2^T for the transposed Jacobian
_DS1_T = np.array([[0, 1, 0, 0], [-1, 0, 0, 0], [0, 0, 0, 1], [0, 0, -1, 0]], dtype=float)
_DS2_T = np.array([[0, 0, 1, 0], [0, 0, 0, 1], [-1, 0, 0, 0], [0, -1, 0, 0]], dtype=float)
_DS1_T_ENTRIES = [((i, r), _DS1_T[i, r]) for i, r in zip(*np.nonzero(_DS1_T), strict=True)]
_DS2_T_ENTRIES = [((i, r), _DS2_T[i, r]) for i, r in zip(*np.nonzero(_DS2_T), strict=True)]


def _jacobian_t(q: np.ndarray, a: np.ndarray, model: str, z_nl: np.ndarray) -> np.ndarray:
    """J_j^T of dq/dt = A q + N(q) z_nl / 2 at the samples q (n, 4), shape (n, 4, 4), from the
    closed form of maslov_terms.nonlinear_jacobian (columns of q, no (n, 4, 4, m) temporaries)."""
    if model == "linear":
        return np.broadcast_to(a.T, (q.shape[0], 4, 4))
    q1, p1, q2, p2 = (np.ascontiguousarray(q[:, i]) for i in range(4))
    energy = q1 * q1 + p1 * p1 + q2 * q2 + p2 * p2
    xp = p2 * q1 - p1 * q2
    xi = z_nl[0]
    alpha, beta = 0.75 * xi * energy, 0.5 * xi * xp
    cu, cw = np.full_like(energy, 1.5 * xi), np.full_like(energy, 0.5 * xi)  # u = cu q + du dxp, w = cw dxp + dw q
    du = dw = None
    if model == "quintic":
        kappa = z_nl[1]
        alpha = alpha + kappa * (0.625 * energy * energy - 0.5 * xp * xp)
        beta = beta + 0.5 * kappa * xp * energy
        cu = cu + 2.5 * kappa * energy
        cw = cw + 0.5 * kappa * energy
        du, dw = -kappa * xp, kappa * xp
    dxp = np.stack([p2, -q2, -p1, q1], axis=-1)
    u = cu[:, None] * q
    w = cw[:, None] * dxp
    if du is not None:
        u += du[:, None] * dxp
        w += dw[:, None] * q
    s12 = np.stack([np.stack([-p1, q1, -p2, q2], axis=-1), np.stack([-q2, -p2, q1, p1], axis=-1)], axis=1)
    jt = np.matmul(np.stack([u, w], axis=-1), s12)  # u s1^T + w s2^T, (n, 4, 2) @ (n, 2, 4)
    jt *= 0.5
    jt += a.T
    half_a, half_b = 0.5 * alpha, 0.5 * beta
    for (i, r), sgn in _DS1_T_ENTRIES:
        jt[:, i, r] += sgn * half_a
    for (i, r), sgn in _DS2_T_ENTRIES:
        jt[:, i, r] += sgn * half_b
    return jt


def _error_map_norm_samples(tr: np.ndarray, n2: np.ndarray, h3: float) -> float:
    """tr(L L^T) for per-sample Jacobians from their traces tr and squared Frobenius norms n2
    (N+1 samples): |I -/+ h3 J|^2 = 4 -/+ 2 h3 tr J + h3^2 |J|^2 (no (N, 4, 4) temporaries)."""
    after = 4.0 * (tr.size - 2) - 2.0 * h3 * tr[2:].sum() + h3 * h3 * n2[2:].sum()
    before = 4.0 * (tr.size - 2) + 2.0 * h3 * tr[:-2].sum() + h3 * h3 * n2[:-2].sum()
    return float(after + 16.0 * h3 * h3 * n2[1:-1].sum() + before)


def _simpson_parts(q: np.ndarray, dt_s: float, model: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(qp, np, y): Simpson states (N-1, 4) and Simpson-integrated nonlinear columns (N-1, 4, m),
    each with two zero blocks either side (qp[j + 1]: block with middle sample j), and the
    differences y; the regressor of block i is (Dg(qs_i) | ns_i), qs = qp[2:-2], ns = np[2:-2]."""
    nl = nonlinear_columns(q, model)
    n_blocks = q.shape[0] - 2
    qp = np.zeros((n_blocks + 4, 4))  # two zero blocks either side, for the sandwich's neighbours
    np_ = np.zeros((n_blocks + 4, 4, nl.shape[-1]))
    qp[2:-2] = simpson_states(q, dt_s)
    np_[2:-2] = nl[:-2] + 4.0 * nl[1:-1] + nl[2:]
    np_[2:-2] *= dt_s / 6.0
    return qp, np_, q[2:] - q[:-2]


def _moments(qs: np.ndarray, ns: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(X^T X, X^T y) of the blocks (Dg(qs_i) | ns_i) from 4x4 / 4x4m moments (X never formed)."""
    m = ns.shape[-1]
    ns2 = ns.reshape(4 * ns.shape[0], m)
    ns_rows = ns.reshape(ns.shape[0], 4 * m)  # (n, 4 m), [a * m + c]
    gg = np.einsum("mn,mak,nal->kl", qs.T @ qs, DG_BASIS, DG_BASIS)
    gn = np.einsum("mac,mak->kc", (qs.T @ ns_rows).reshape(4, 4, m), DG_BASIS)
    xtx = np.block([[gg, gn], [gn.T, ns2.T @ ns2]])
    xty = np.concatenate([np.einsum("ma,mak->k", qs.T @ y, DG_BASIS), ns2.T @ y.reshape(-1)])
    return xtx, xty


def _window_maps(m: int) -> tuple[np.ndarray, np.ndarray]:
    """Constant maps from the windows (qs_{j-1}, qs_j, qs_{j+1}) (12) and (ns_{j-1}, ns_j, ns_{j+1})
    (12 m) of sample j to (X_{j-1} - X_{j+1} | X_{j-1} + 4 X_j + X_{j+1}) flattened, 2 x (4, 8 + m)."""
    k = 8 + m
    mq = np.zeros((3, 4, 2, 4, k))
    mn = np.zeros((3, 4, m, 2, 4, k))
    for w, (wd, ws) in enumerate(((1.0, 1.0), (0.0, 4.0), (-1.0, 1.0))):
        mq[w, :, 0, :, :8], mq[w, :, 1, :, :8] = wd * DG_BASIS, ws * DG_BASIS
        for a in range(4):
            for c in range(m):
                mn[w, a, c, 0, a, 8 + c], mn[w, a, c, 1, a, 8 + c] = wd, ws
    return mq.reshape(12, 8 * k), mn.reshape(12 * m, 8 * k)


def _windows(rows: np.ndarray, s: int, e: int) -> np.ndarray:
    """(rows[s], rows[s + 1], rows[s + 2]) flattened for each of s..e-1: a strided view, no copy."""
    flat = rows.reshape(rows.shape[0], -1)
    width = flat.shape[1]
    return np.lib.stride_tricks.as_strided(flat[s:], shape=(e - s, 3 * width), strides=flat.strides, writeable=False)


def _sandwich(q: np.ndarray, dt_s: float, model: str, z: np.ndarray, qp: np.ndarray, npd: np.ndarray,
              y: np.ndarray) -> dict:
    """Residuals, meat sum_j F_j^T F_j and tr(L L^T) of the module docstring at parameters z
    (qp, npd: the padded Simpson parts of _simpson_parts)."""
    qs, ns = qp[2:-2], npd[2:-2]
    n_samples, m = q.shape[0], ns.shape[-1]
    k = 8 + m
    a = linear_matrix(z[:8])
    h3 = dt_s / 3.0
    resid = y - qs @ (2.0 * a).T - (ns.reshape(4 * ns.shape[0], m) @ z[8:]).reshape(-1, 4)
    meat = np.zeros((k, k))
    tr, n2 = np.empty(n_samples), np.empty(n_samples)
    map_q, map_n = _window_maps(m)
    for s in range(0, n_samples, _CHUNK):
        e = min(s + _CHUNK, n_samples)
        both = _windows(qp, s, e) @ map_q
        if m:
            both += _windows(npd, s, e) @ map_n
        both = both.reshape(e - s, 2, 4, k)
        x_diff, x_sum = both[:, 0], both[:, 1]
        jt = _jacobian_t(q[s:e], a, model, z[8:])
        f = x_diff - h3 * np.matmul(jt, x_sum)  # F_j = (X_{j-1} - X_{j+1}) - h3 J_j^T (X_{j-1} + 4 X_j + X_{j+1})
        f2 = f.reshape(-1, k)
        meat += f2.T @ f2
        tr[s:e] = np.einsum("jaa->j", jt)
        n2[s:e] = np.einsum("jab,jab->j", jt, jt)
    lnorm = _error_map_norm(a, h3, qs.shape[0]) if model == "linear" else _error_map_norm_samples(tr, n2, h3)
    return {"resid": resid, "meat": meat, "lnorm": lnorm}


def _general_fit(q: np.ndarray, dt_s: float, model: str, recursive: bool, n_init: int | None) -> dict:
    """Batch fit from regressor moments, or the recursive form over the Simpson blocks; then the sandwich."""
    qp, npd, y = _simpson_parts(q, dt_s, model)
    qs, ns = qp[2:-2], npd[2:-2]
    n_blocks = qs.shape[0]
    k = 8 + ns.shape[-1]
    if recursive:
        if n_init is None:  # a batch start on 2 % of the record, at least 4 x k blocks, at most all
            m = min(max(4 * k, n_blocks // 50), n_blocks)
            if m < k:
                raise ValueError(f"{n_blocks} Simpson blocks are too few for the {k} parameters of model={model!r}")
        else:
            m = n_init
            if not k <= m <= n_blocks:
                raise ValueError(f"n_init_blocks={m} must be between {k} and the {n_blocks} blocks")
        z, c = _recursive_from_parts(qs, ns, y, int(m))
    else:
        xtx, xty = _moments(qs, ns, y)
        c = np.linalg.inv(xtx)
        z = np.linalg.solve(xtx, xty)
    return {"z": z, "c": c, **_sandwich(q, dt_s, model, z, qp, npd, y)}


def _rls_chunk(z: np.ndarray, p: np.ndarray, h: np.ndarray, g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One step of eq. 2.12 for a block D of any height from h = D^T D and g = D^T (y - D z) (the
    residual formed per equation first: D^T y - h z would cancel).  With P = L L^T the push-through
    identity gives S = P D^T (I + D P D^T)^-1 = L M^-1 L^T D^T, M = I + L^T h L (small, symmetric,
    eigenvalues 1 .. 1 + new/old information), so z += L M^-1 L^T g and P -= S D P = L M^-1 L^T.
    Applied to a stack of 4x4 blocks it gives what their 4x4 updates in turn give (each update is
    the exact posterior of the equations so far), without any 4B x 4B inverse."""
    chol = np.linalg.cholesky(0.5 * (p + p.T))
    m = np.eye(p.shape[0]) + chol.T @ h @ chol
    sol = np.linalg.solve(m, np.hstack([chol.T, (chol.T @ g)[:, None]]))
    return z + chol @ sol[:, -1], chol @ sol[:, :-1]


def _recursive_from_parts(qs: np.ndarray, ns: np.ndarray, y: np.ndarray, n_init_blocks: int,
                          chunk_blocks: int = _RLS_CHUNK) -> tuple[np.ndarray, np.ndarray]:
    """recursive_lsq on the blocks (Dg(qs_i) | ns_i) with the chunk moments from 4x4 moments."""
    xtx, xty = _moments(qs[:n_init_blocks], ns[:n_init_blocks], y[:n_init_blocks])
    p = np.linalg.inv(xtx)
    z = p @ xty
    for lo in range(n_init_blocks, qs.shape[0], chunk_blocks):
        hi = lo + chunk_blocks
        qs_c, ns_c = qs[lo:hi], ns[lo:hi]
        resid = y[lo:hi] - qs_c @ (2.0 * linear_matrix(z[:8])).T
        resid -= (ns_c.reshape(4 * qs_c.shape[0], -1) @ z[8:]).reshape(-1, 4)
        z, p = _rls_chunk(z, p, *_moments(qs_c, ns_c, resid))
    return z, 0.5 * (p + p.T)


def recursive_lsq(x: np.ndarray, y: np.ndarray, n_init_blocks: int, *,
                  chunk_blocks: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """The paper's recursive least squares (eq. 2.12) with 4x4 blocks: batch start on the first
    n_init_blocks blocks, then for each block with regressor D (4 x k) and r = D^T:
        S = P r (I + r^T P r)^-1,  z += S (y - D z),  P -= S r^T P.
    chunk_blocks > 1 applies the updates of that many 4x4 blocks at once (`_rls_chunk`: equal to
    applying them in turn, vectorised); chunk_blocks = 1 is the literal 4x4 loop.
    Returns (z, P); P = (X^T X)^-1 of all blocks."""
    if int(chunk_blocks) < 1:
        raise ValueError(f"chunk_blocks={chunk_blocks!r} must be at least 1")
    n_blocks, _, k = x.shape
    x0 = x[:n_init_blocks].reshape(-1, k)
    p = np.linalg.inv(x0.T @ x0)
    z = p @ (x0.T @ y[:n_init_blocks].reshape(-1))
    if chunk_blocks > 1:
        for lo in range(n_init_blocks, n_blocks, int(chunk_blocks)):
            d = x[lo : lo + int(chunk_blocks)].reshape(-1, k)
            z, p = _rls_chunk(z, p, d.T @ d, d.T @ (y[lo : lo + int(chunk_blocks)].reshape(-1) - d @ z))
        return z, 0.5 * (p + p.T)
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
    method: str = "equation-error",
    covariance: str = "fisher",
    max_iter: int = 50,
    rotation_basis: np.ndarray | None = None,
) -> Identification:
    """Identify (gamma, nu, b_c, b_s, c_m, n, h_c, h_s[, xi[, kappa]]) from a free decay sampled
    uniformly.  detuning_hz: demodulation reference minus natural frequency (the fit sees
    c_m - 2 lam; c_m is reported with 2 lam added back).  natural_freq_hz enables Q, bryan_factor
    the zero-rate output in `derived`.  ci95 is the sandwich interval of the module docstring.

    method="equation-error" (default): the paper's Simpson least squares (batch, or recursive=True).
    method="output-error": maximum likelihood under white noise (`free_decay_oe`), started from the
    equation-error estimate, which `recursive` and n_init_blocks select as above (the optimum does
    not depend on the start); covariance="fisher" or "sandwich" (Newey-West, coloured noise) and
    max_iter (FreeDecayFitError beyond it) and rotation_basis (known harmonics of an output rotation,
    e.g. a rate table's angle ripple, fitted as nuisance) apply to it only; extras["start"] holds
    the start."""
    if method not in FREE_DECAY_METHODS:
        raise ValueError(f"method={method!r} is not one of {FREE_DECAY_METHODS}")
    if method == "output-error":
        from bench.analysis.free_decay_oe import COVARIANCES, identification_from_oe, output_error_fit

        if covariance not in COVARIANCES:
            raise ValueError(f"covariance={covariance!r} is not one of {COVARIANCES}")
        ee = identify_free_decay(t_s, q1, p1, q2, p2, model=model, recursive=recursive, n_init_blocks=n_init_blocks,
                                 level=level)
        q = np.stack([q1, p1, q2, p2], axis=-1).astype(float)
        fit = output_error_fit(np.asarray(t_s, dtype=float), q, ee.vector(), model=model, covariance=covariance,
                               max_iter=max_iter, rotation_basis=rotation_basis)
        return identification_from_oe(fit, model, detuning_hz=detuning_hz, level=level,
                                      natural_freq_hz=natural_freq_hz, bryan_factor=bryan_factor,
                                      start=ee.params, dt_s=float(ee.extras["dt_s"]), covariance=covariance)
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
