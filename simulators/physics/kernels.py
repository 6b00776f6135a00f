"""Compiled (numba) kernels of the resonator's exact linear step: a World block in one call.

A block of the 50 ms loops costs a few microseconds here instead of ~100 us of small-array numpy
(a scipy expm of the 8x8 augmented matrix, its powers and a wave rotation per block: the PLL moves
the reference every block, so nothing could be cached).  `cache=True` keeps the compiled code on
disk (next to this file, or numba's user cache when that is read-only), so only the first run
after an install pays the compile.
"""

from __future__ import annotations

import numpy as np

from bench.kernel_cache import njit  # NUMBA_CACHE_DIR keyed on the kernels' sources

_TAYLOR_MAX_NORM = 0.125  # scale A h below this: the series then converges in ~14 terms
_TAYLOR_TOL = 1e-18


@njit(cache=True)
def linear_matrix_into(zg: np.ndarray, lam: float, a: np.ndarray) -> None:
    """a = slow_model.linear_matrix(zg, lam) (dq/dt = A q), written out: 0.5 (Dg zg - 2 lam J)."""
    g, nu, bc, bs, cm, n, hc, hs = zg[0], zg[1], zg[2], zg[3], zg[4], zg[5], zg[6], zg[7]
    two_lam = 2.0 * lam
    a[0, 0], a[0, 1], a[0, 2], a[0, 3] = -(g + bc), cm + hc - two_lam, nu - bs, n + hs
    a[1, 0], a[1, 1], a[1, 2], a[1, 3] = -(cm + hc) + two_lam, -(g + bc), -(n + hs), nu - bs
    a[2, 0], a[2, 1], a[2, 2], a[2, 3] = -nu - bs, -n + hs, -g + bc, cm - hc - two_lam
    a[3, 0], a[3, 1], a[3, 2], a[3, 3] = n - hs, -nu - bs, -cm + hc + two_lam, -g + bc
    for i in range(4):
        for j in range(4):
            a[i, j] *= 0.5


@njit(cache=True)
def _matmul4(x: np.ndarray, y: np.ndarray, out: np.ndarray) -> None:
    for i in range(4):
        for j in range(4):
            acc = 0.0
            for k in range(4):
                acc += x[i, k] * y[k, j]
            out[i, j] = acc


@njit(cache=True)
def exact_step_matrices(a: np.ndarray, dt: float, phi: np.ndarray, gam: np.ndarray) -> None:
    """phi = exp(A dt) and gam = 1/2 int_0^dt exp(A s) ds, i.e. the top row of the exponential of
    the augmented [[A, I/2], [0, 0]] dt: Taylor series of A h (h = dt / 2^s, |A h| <= 1/8), then
    s squarings [[P, G], [0, I]]^2 = [[P P, P G + G], [0, I]]."""
    norm = 0.0
    for i in range(4):
        row = 0.0
        for j in range(4):
            row += abs(a[i, j])
        norm = max(norm, row)
    h = dt
    norm *= dt
    s = 0
    while norm > _TAYLOR_MAX_NORM:
        norm *= 0.5
        h *= 0.5
        s += 1
    # element by element (the same products and sums as the array expressions `a * h`,
    # `np.eye(4) * h`, `g += tmp`, `p[:, :] = tmp`): numba compiles loops in a fraction of the time
    # it takes for array expressions and their shape checks (benchmarks/first_run.py)
    ah = np.empty((4, 4))
    term = np.zeros((4, 4))
    nxt = np.empty((4, 4))
    p = np.zeros((4, 4))
    g = np.zeros((4, 4))
    for i in range(4):
        for j in range(4):
            ah[i, j] = a[i, j] * h
        term[i, i] = 1.0
        p[i, i] = 1.0
    for i in range(4):
        for j in range(4):
            g[i, j] = p[i, j] * h
    for k in range(1, 40):
        _matmul4(term, ah, nxt)
        big = 0.0
        for i in range(4):
            for j in range(4):
                t = nxt[i, j] / k
                term[i, j] = t
                p[i, j] += t
                g[i, j] += t * (h / (k + 1))
                big = max(big, abs(t))
        if big < _TAYLOR_TOL:
            break
    tmp = np.empty((4, 4))
    for _ in range(s):
        _matmul4(p, g, tmp)
        for i in range(4):
            for j in range(4):
                g[i, j] += tmp[i, j]
        _matmul4(p, p, tmp)
        for i in range(4):
            for j in range(4):
                p[i, j] = tmp[i, j]
    for i in range(4):
        for j in range(4):
            phi[i, j] = p[i, j]
            gam[i, j] = 0.5 * g[i, j]


@njit(cache=True)
def linear_block(
    zg: np.ndarray,
    lam: float,
    dt: float,
    q: np.ndarray,
    u: np.ndarray,
    ripple: np.ndarray,
    psi_per_rad: float,
    out: np.ndarray,
    noise: np.ndarray,
    sigma: float,
    gain_x: float = 1.0,
    gain_y: float = 1.0,
) -> None:
    """Exact steps of dq/dt = A(zg, lam) q + u/2 from q over len(out) samples into out (n, 4);
    q ends as the last (unrotated) state.  With a ripple (n,) (rad; empty for none), out is
    rotated by psi = psi_per_rad * ripple electrical.  With noise (n, 4) standard normals (empty
    for none), noise becomes the measured states out + sigma * noise, times the pickoff gains
    (gain_x on cx, sx; gain_y on cy, sy: the same products as scaling afterwards).  Inputs are
    held over the block."""
    a = np.empty((4, 4))
    linear_matrix_into(zg, lam, a)
    phi = np.empty((4, 4))
    gam = np.empty((4, 4))
    exact_step_matrices(a, dt, phi, gam)
    b = np.empty(4)
    for i in range(4):
        b[i] = gam[i, 0] * u[0] + gam[i, 1] * u[1] + gam[i, 2] * u[2] + gam[i, 3] * u[3]
    x0, x1, x2, x3 = q[0], q[1], q[2], q[3]
    for k in range(out.shape[0]):
        y0 = phi[0, 0] * x0 + phi[0, 1] * x1 + phi[0, 2] * x2 + phi[0, 3] * x3 + b[0]
        y1 = phi[1, 0] * x0 + phi[1, 1] * x1 + phi[1, 2] * x2 + phi[1, 3] * x3 + b[1]
        y2 = phi[2, 0] * x0 + phi[2, 1] * x1 + phi[2, 2] * x2 + phi[2, 3] * x3 + b[2]
        y3 = phi[3, 0] * x0 + phi[3, 1] * x1 + phi[3, 2] * x2 + phi[3, 3] * x3 + b[3]
        out[k, 0] = y0
        out[k, 1] = y1
        out[k, 2] = y2
        out[k, 3] = y3
        x0, x1, x2, x3 = y0, y1, y2, y3
    q[0], q[1], q[2], q[3] = x0, x1, x2, x3
    if ripple.shape[0] > 0:
        for k in range(out.shape[0]):
            psi = psi_per_rad * ripple[k]
            c, s = np.cos(psi), np.sin(psi)
            q1, p1, q2, p2 = out[k, 0], out[k, 1], out[k, 2], out[k, 3]
            out[k, 0] = q1 * c - q2 * s
            out[k, 1] = p1 * c - p2 * s
            out[k, 2] = q1 * s + q2 * c
            out[k, 3] = p1 * s + p2 * c
    if noise.shape[0] > 0:  # as rng.normal(0, sigma) added: q + (0 + sigma z)
        if gain_x == 1.0 and gain_y == 1.0:
            for k in range(out.shape[0]):
                for i in range(4):
                    noise[k, i] = out[k, i] + (0.0 + sigma * noise[k, i])
        else:
            for k in range(out.shape[0]):
                noise[k, 0] = (out[k, 0] + (0.0 + sigma * noise[k, 0])) * gain_x
                noise[k, 1] = (out[k, 1] + (0.0 + sigma * noise[k, 1])) * gain_x
                noise[k, 2] = (out[k, 2] + (0.0 + sigma * noise[k, 2])) * gain_y
                noise[k, 3] = (out[k, 3] + (0.0 + sigma * noise[k, 3])) * gain_y



@njit(cache=True)
def drift_noise_fill(
    gen_white: np.random.Generator,
    white_sd: float,
    gen_flicker: np.random.Generator,
    gm_phi: np.ndarray,
    gm_drive: np.ndarray,
    gm_state: np.ndarray,
    gen_walk: np.random.Generator,
    walk_sd: float,
    walk_state: np.ndarray,
    out: np.ndarray,
) -> None:
    """The drift-rate noise (rad/s) of the next len(out) samples into out: white (sd white_sd per
    sample), a sum of first-order Gauss-Markov processes (x <- phi x + drive z each sample: the
    flicker) and a random walk (steps of sd walk_sd).  Each process draws from its own generator;
    the states carry over to the next call.  Called for a chunk of samples at a time: passing the
    generators costs ~10 us a call, the draws ~5 ns each."""
    walk = walk_state[0]
    m = gm_state.shape[0]
    for k in range(out.shape[0]):
        s = 0.0
        if white_sd != 0.0:
            s += white_sd * gen_white.standard_normal()
        if walk_sd != 0.0:
            walk += walk_sd * gen_walk.standard_normal()
            s += walk
        for j in range(m):
            x = gm_phi[j] * gm_state[j] + gm_drive[j] * gen_flicker.standard_normal()
            gm_state[j] = x
            s += x
        out[k] = s
    walk_state[0] = walk
