"""Compiled per-block work of the simulated front end: its lock-in's first-order low-pass."""

from __future__ import annotations

import numpy as np

from bench.kernel_cache import njit  # NUMBA_CACHE_DIR keyed on the kernels' sources


@njit(cache=True)
def lockin_fold(y: np.ndarray, q: np.ndarray, n: int, weights: np.ndarray, carry: float) -> None:
    """Fold blocks of n samples of q (m, 4), m a multiple of n, into the lock-in output y (4,) in
    place, block by block: y = carry y + sum_k weights[k] q_k (the low-pass y_k = a q_k + (1 - a)
    y_(k-1) over a block keeps only its last output: weights a (1 - a)^(n-1-k), carry (1 - a)^n),
    the sum taken in sample order (the same numbers on every machine, unlike a BLAS product)."""
    for b in range(q.shape[0] // n):
        r0 = b * n
        for c in range(4):
            s = 0.0
            for k in range(n):
                s += weights[k] * q[r0 + k, c]
            y[c] = carry * y[c] + s
