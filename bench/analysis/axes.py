"""The one convention for a principal axis of the n = 2 mode (theta_tau, theta_w, Maslov's alpha
and beta): an angle in [0, 90) deg, since the axes repeat every 90 deg (docs/angle_convention.md).
Every estimate is brought into it here, its interval shifted with it."""

from __future__ import annotations

import math

AXIS_PERIOD_DEG = 90.0


def axis_deg(value_deg: float) -> float:
    """An axis angle in [0, 90) deg."""
    v = float(value_deg) % AXIS_PERIOD_DEG
    return 0.0 if v >= AXIS_PERIOD_DEG else v  # -1e-17 % 90 is 90.0 in floating point


def axis_with_interval(value_deg: float, ci95_deg: tuple[float, float] | None
                       ) -> tuple[float, tuple[float, float] | None]:
    """(value in [0, 90), its interval shifted by the same multiple of 90 deg); the interval may
    leave [0, 90) (an axis near 0 deg has an interval such as [-1.2, 2.3])."""
    if not math.isfinite(value_deg):
        return value_deg, ci95_deg
    wrapped = axis_deg(value_deg)
    shift = wrapped - float(value_deg)
    if ci95_deg is None:
        return wrapped, None
    return wrapped, (float(ci95_deg[0]) + shift, float(ci95_deg[1]) + shift)
