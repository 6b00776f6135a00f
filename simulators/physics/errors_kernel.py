"""Compiled (numba) kernel of the pickoff chains' error sources on a block of measured states.

`ErrorSources.measure` on a (n, 4) block was ~25 small numpy calls (~30 us a block, the largest
per-block cost of a thermal run in the profile of tests/test_thermal_soak.py); here one loop does
the same operations on each element in the same order (no fused multiply-add: numba's default is
strict IEEE arithmetic), so every value is the one the numpy form gave
(tests/test_error_sources.py checks bit for bit).
"""

from __future__ import annotations

import numpy as np

from bench.kernel_cache import njit  # NUMBA_CACHE_DIR keyed on the kernels' sources


@njit(cache=True)
def pickoff_block(
    q: np.ndarray,
    rotate: bool,
    cos_ax: float,
    sin_ax: float,
    cos_ay: float,
    sin_ay: float,
    e3: float,
    phase_x: bool,
    cos_px: float,
    sin_px: float,
    phase_y: bool,
    cos_py: float,
    sin_py: float,
    gx: float,
    gy: float,
    out: np.ndarray,
) -> None:
    """out (n, 4) = the states q (n, 4) as the pickoff chains read them: the electrodes' projection
    (when `rotate`), the cubic nonlinearity (when e3), each chain's phase delay, then its gain."""
    k3 = 0.75 * e3
    neg_sin_ay = -sin_ay
    for i in range(q.shape[0]):
        cx, sx, cy, sy = q[i, 0], q[i, 1], q[i, 2], q[i, 3]
        if rotate:  # X at ex reads x cos 2ex + y sin 2ex; Y at 45 deg + ey reads -x sin 2ey + y cos 2ey
            cx, cy = cos_ax * cx + sin_ax * cy, neg_sin_ay * cx + cos_ay * cy
            sx, sy = cos_ax * sx + sin_ax * sy, neg_sin_ay * sx + cos_ay * sy
        if e3 != 0.0:  # the fundamental of (x + e3 x^3): x (1 + (3/4) e3 |x|^2) on each channel
            fx = 1.0 + k3 * (cx * cx + sx * sx)
            fy = 1.0 + k3 * (cy * cy + sy * sy)
            cx, sx, cy, sy = cx * fx, sx * fx, cy * fy, sy * fy
        if phase_x:  # x(t - d) = (c cos p - s sin p) cos wt + (c sin p + s cos p) sin wt, p = w d
            cx, sx = cx * cos_px - sx * sin_px, cx * sin_px + sx * cos_px
        if phase_y:
            cy, sy = cy * cos_py - sy * sin_py, cy * sin_py + sy * cos_py
        out[i, 0], out[i, 1], out[i, 2], out[i, 3] = gx * cx, gx * sx, gy * cy, gy * sy
