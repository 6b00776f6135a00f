"""Compiled (numba) fixed-step integration of the nonlinear slow-variable model and its sensitivity
equations on a uniform sample grid, for the output-error fit (`free_decay_oe`).

Classical RK4 with m equal substeps per sample step, m chosen from the fastest rate of the model
(linear eigenvalues and the amplitude-dependent frequency) so that rate x substep <= `RK_RATE_STEP`:
its error is far below the noise of any record (benchmarks/free_decay_crlb.py checks the fit's
scatter against the CRLB) and it is ~100 times faster than DOP853 with a Python right-hand side.
"""

from __future__ import annotations

import math

import numpy as np

from bench.kernel_cache import njit  # NUMBA_CACHE_DIR keyed on the kernels' sources

RK_RATE_STEP = 0.01  # rad per RK4 substep at the model's fastest rate: local error ~ 1e-12


@njit(cache=True)
def _deriv(q: np.ndarray, s: np.ndarray, a: np.ndarray, bmat: np.ndarray, xi_h: float, kap_h: float,
           quintic: bool, jac: bool, dq: np.ndarray, ds: np.ndarray) -> None:
    """dq/dt = A q + N(q) z_nl / 2 and, with jac, dS/dt = J(q) S + [0 | B_j q | N(q) / 2].

    xi_h, kap_h are xi / 2, kappa / 2; bmat (8, 4, 4) the dA/dz_j."""
    q1, p1, q2, p2 = q[0], q[1], q[2], q[3]
    av = (-p1, q1, -p2, q2)  # a = DA q
    bv = (-q2, -p2, q1, p1)  # b = DB q
    energy = q1 * q1 + p1 * p1 + q2 * q2 + p2 * p2
    x = p2 * q1 - p1 * q2
    e3, x2 = 0.75 * energy, 0.5 * x
    ca, cb = xi_h * e3, xi_h * x2
    s5 = 0.625 * energy * energy - 0.5 * x * x
    c5 = 0.5 * x * energy
    if quintic:
        ca += kap_h * s5
        cb += kap_h * c5
    for i in range(4):
        acc = av[i] * ca + bv[i] * cb
        for j in range(4):
            acc += a[i, j] * q[j]
        dq[i] = acc
    if not jac:
        return
    qv = (q1, p1, q2, p2)
    dx = (p2, -q2, -p1, q1)
    jm = np.empty((4, 4))
    for j in range(4):
        ga = 1.5 * xi_h * qv[j]
        gb = 0.5 * xi_h * dx[j]
        if quintic:
            ga += kap_h * (2.5 * energy * qv[j] - x * dx[j])
            gb += kap_h * (0.5 * energy * dx[j] + x * qv[j])
        for i in range(4):
            jm[i, j] = a[i, j] + av[i] * ga + bv[i] * gb
    # + ca DA + cb DB (DA q = av, DB q = bv)
    jm[0, 1] -= ca
    jm[1, 0] += ca
    jm[2, 3] -= ca
    jm[3, 2] += ca
    jm[0, 2] -= cb
    jm[1, 3] -= cb
    jm[2, 0] += cb
    jm[3, 1] += cb
    p = s.shape[1]
    for i in range(4):
        for c in range(p):
            acc = 0.0
            for j in range(4):
                acc += jm[i, j] * s[j, c]
            ds[i, c] = acc
        for c in range(8):
            acc = 0.0
            for j in range(4):
                acc += bmat[c, i, j] * q[j]
            ds[i, 4 + c] += acc
        ds[i, 12] += 0.5 * (av[i] * e3 + bv[i] * x2)
        if quintic:
            ds[i, 13] += 0.5 * (av[i] * s5 + bv[i] * c5)


@njit(cache=True)
def rk4_sensitivities(a: np.ndarray, bmat: np.ndarray, xi: float, kappa: float, quintic: bool, q0: np.ndarray,
                      n: int, dt_s: float, substeps: int, jac: bool) -> tuple[np.ndarray, np.ndarray]:
    """Trajectory (n, 4) at k dt_s, k = 0..n-1, from q0 and, with jac, its sensitivities
    (n, 4, 4 + k) to (q0, z), k = 9 (cubic) or 10 (quintic); S(0) = [I | 0]."""
    p = 4 + 8 + (2 if quintic else 1)
    ps = p if jac else 0
    out_q = np.empty((n, 4))
    out_s = np.zeros((n if jac else 0, 4, p))
    q = q0.copy()
    s = np.zeros((4, ps))
    for i in range(4 if jac else 0):
        s[i, i] = 1.0
    xi_h, kap_h = 0.5 * xi, 0.5 * kappa
    h = dt_s / substeps
    k1q, k2q, k3q, k4q, tq = np.empty(4), np.empty(4), np.empty(4), np.empty(4), np.empty(4)
    k1s, k2s, k3s, k4s, ts = (np.empty((4, ps)), np.empty((4, ps)), np.empty((4, ps)), np.empty((4, ps)),
                              np.empty((4, ps)))
    out_q[0] = q
    if jac:
        out_s[0] = s
    for k in range(1, n):
        for _ in range(substeps):
            _deriv(q, s, a, bmat, xi_h, kap_h, quintic, jac, k1q, k1s)
            tq[:] = q + 0.5 * h * k1q
            ts[:] = s + 0.5 * h * k1s
            _deriv(tq, ts, a, bmat, xi_h, kap_h, quintic, jac, k2q, k2s)
            tq[:] = q + 0.5 * h * k2q
            ts[:] = s + 0.5 * h * k2s
            _deriv(tq, ts, a, bmat, xi_h, kap_h, quintic, jac, k3q, k3s)
            tq[:] = q + h * k3q
            ts[:] = s + h * k3s
            _deriv(tq, ts, a, bmat, xi_h, kap_h, quintic, jac, k4q, k4s)
            q += (h / 6.0) * (k1q + 2.0 * k2q + 2.0 * k3q + k4q)
            s += (h / 6.0) * (k1s + 2.0 * k2s + 2.0 * k3s + k4s)
        out_q[k] = q
        if jac:
            out_s[k] = s
    return out_q, out_s


def substeps_for(a: np.ndarray, xi: float, kappa: float, q0: np.ndarray, dt_s: float) -> int:
    """RK4 substeps per sample step: the fastest rate (|eig A| plus the nonlinear frequency at the
    start's energy, which only falls in a decay) times the substep <= RK_RATE_STEP."""
    energy = float(np.dot(q0, q0))
    rate = float(np.max(np.abs(np.linalg.eigvals(a)))) + 0.5 * (abs(xi) * 1.5 * energy + abs(kappa) * 3.0 * energy**2)
    return max(1, math.ceil(rate * dt_s / RK_RATE_STEP))
