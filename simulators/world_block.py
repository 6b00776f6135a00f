"""One block of the world's samples (its index, times, true and measured states, case rate and
angle): what the world hands its devices after each block, and what its fused path
(simulators.fused) hands them after a run of blocks.  Its own module so that both import it and
neither imports the other's caller."""

from __future__ import annotations

import numpy as np


class WorldBlock:
    """The samples of one block: index and time of each sample end, true and measured states,
    case rate and case angle.  The index, time, rate and angle arrays are made on first access
    (most devices need only `first_index` and `n`)."""

    __slots__ = (
        "first_index", "n", "q_true", "q_meas", "_rate", "_angle0", "_ripple_rad", "_dt",
        "_index", "_t", "_rate_arr", "_angle",
    )  # fmt: skip

    def __init__(
        self,
        first_index: int,  # sample number (since the world started) of the block's first sample
        q_true: np.ndarray,  # (n, 4) cx, sx, cy, sy without noise
        q_meas: np.ndarray,  # (n, 4) with the pickoff noise
        rate_dps: float,  # case rate held over the block (without ripple)
        angle0_deg: float,  # case angle at the block's start
        dt_s: float,  # sample period
        ripple_angle_rad: np.ndarray | None = None,  # (n,) in-block angle deviation, or None
    ) -> None:
        self.first_index, self.n, self.q_true, self.q_meas = first_index, len(q_true), q_true, q_meas
        self._rate, self._angle0, self._ripple_rad, self._dt = rate_dps, angle0_deg, ripple_angle_rad, dt_s
        self._index: np.ndarray | None = None
        self._t: np.ndarray | None = None
        self._rate_arr: np.ndarray | None = None
        self._angle: np.ndarray | None = None

    @property
    def index(self) -> np.ndarray:
        """(n,) int64 sample numbers since the world started."""
        if self._index is None:
            self._index = np.arange(self.first_index, self.first_index + self.n, dtype=np.int64)
        return self._index

    @property
    def t_s(self) -> np.ndarray:
        """(n,) time of each sample's end: index x sample period."""
        if self._t is None:
            self._t = self.index * self._dt
        return self._t

    @property
    def rate_dps(self) -> np.ndarray:
        """(n,) case rate (with ripple)."""
        if self._rate_arr is None:
            rate_arr = np.full(self.n, self._rate)
            if self._ripple_rad is not None and self.n > 1:
                rate_arr = rate_arr + _gradient(np.degrees(self._ripple_rad), self._dt)
            self._rate_arr = rate_arr
        return self._rate_arr

    @property
    def angle_deg(self) -> np.ndarray:
        """(n,) case angle."""
        if self._angle is None:
            angle = self._angle0 + self._rate * (self.t_s - (self.first_index - 1) * self._dt)
            if self._ripple_rad is not None:
                angle = angle + np.degrees(self._ripple_rad)
            self._angle = angle
        return self._angle


def _gradient(f: np.ndarray, dx: float) -> np.ndarray:
    """np.gradient(f, dx) of a 1-D array of >= 2 samples, same arithmetic (central differences,
    one-sided at the ends) without its generic-axis overhead."""
    out = np.empty_like(f)
    out[1:-1] = (f[2:] - f[:-2]) / (2.0 * dx)
    out[0] = (f[1] - f[0]) / dx
    out[-1] = (f[-1] - f[-2]) / dx
    return out
