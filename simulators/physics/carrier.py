"""Carrier-level two-mode equations of motion and a software I/Q demodulator.

The averaged model of `averaged.py` is what the averaging method gives from these equations,
with x = f, y = g the two pickoff coordinates and w the reference (drive) frequency:
    f'' + w0^2 f = -(gamma + b_c) f' + (nu - b_s) g' - w0[(c_m + h_c) f + (h_s + n) g]
                   + w0 xi (f^2+g^2) f + w0 kappa (f^2+g^2)^2 f + w (u2 cos wt - u1 sin wt)
    g'' + w0^2 g = -(gamma - b_c) g' - (nu + b_s) f' - w0[(c_m - h_c) g + (h_s - n) f]
                   + w0 xi (f^2+g^2) g + w0 kappa (f^2+g^2)^2 g + w (u4 cos wt - u3 sin wt)
Integrating them resolves every carrier cycle, so it is only for short checks (tests use a low
carrier frequency to keep them quick); demodulating the result must give back the slow states.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.integrate import solve_ivp

from .params import TWO_PI, ResonatorParams


def integrate_carrier(
    params: ResonatorParams,
    q0: np.ndarray,
    duration_s: float,
    *,
    fs_hz: float,
    rate_rad_s: float = 0.0,
    force: np.ndarray | None = None,
    ref_freq_hz: float | None = None,
    rtol: float = 1e-10,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Integrate the two-mode equations from slow state q0; return (t_s, x, y) sampled at fs_hz.

    The reference phase is w t with w = 2 pi ref_freq_hz (default the nominal frequency), so
    x = cx cos wt + sx sin wt at t = 0 matches q0."""
    c = params.coefficients()
    w0 = c.w0_rad_s
    w = TWO_PI * (params.f0_hz if ref_freq_hz is None else ref_freq_hz)
    nu = 4.0 * c.bryan_factor * rate_rad_s + c.nu_offset
    u = np.zeros(4) if force is None else np.asarray(force, dtype=float)
    q1, p1, q2, p2 = np.asarray(q0, dtype=float)
    # f = p1 sin wt + q1 cos wt, f' = w (p1 cos wt - q1 sin wt) at t = 0
    y0 = np.array([q1, p1 * w, q2, p2 * w])

    def rhs(t: float, s: np.ndarray) -> np.ndarray:
        f, fd, g, gd = s
        r2 = f * f + g * g
        nl = w0 * (c.xi * r2 + c.kappa * r2 * r2)
        cw, sw = math.cos(w * t), math.sin(w * t)
        fdd = (
            -w0 * w0 * f
            - (c.gamma + c.b_c) * fd
            + (nu - c.b_s) * gd
            - w0 * ((c.c_m + c.h_c) * f + (c.h_s + c.n) * g)
            + nl * f
            + w * (u[1] * cw - u[0] * sw)
        )
        gdd = (
            -w0 * w0 * g
            - (c.gamma - c.b_c) * gd
            - (nu + c.b_s) * fd
            - w0 * ((c.c_m - c.h_c) * g + (c.h_s - c.n) * f)
            + nl * g
            + w * (u[3] * cw - u[2] * sw)
        )
        return np.array([fd, fdd, gd, gdd])

    n = int(round(duration_s * fs_hz)) + 1
    t_eval = np.arange(n) / fs_hz
    sol = solve_ivp(rhs, (0.0, t_eval[-1]), y0, t_eval=t_eval, method="DOP853", rtol=rtol, atol=1e-12)
    if not sol.success:  # pragma: no cover
        raise RuntimeError(f"carrier integration failed: {sol.message}")
    return sol.t, sol.y[0], sol.y[2]


def iq_demodulate(
    t_s: np.ndarray, signal: np.ndarray, ref_freq_hz: float, fs_hz: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Software I/Q demodulator: mix with 2 cos wt and 2 sin wt and average over exactly one
    reference period (a boxcar whose nulls fall on the 2w image).  Returns (t_center, c, s),
    c and s the envelopes of signal = c cos wt + s sin wt at the window centres."""
    period = int(round(fs_hz / ref_freq_hz))
    if period < 4:
        raise ValueError(f"sample rate {fs_hz} Hz gives {period} samples per reference period; need >= 4")
    if abs(period - fs_hz / ref_freq_hz) > 1e-9 * period:
        raise ValueError("fs_hz must be an integer multiple of ref_freq_hz for an exact boxcar")
    w = TWO_PI * ref_freq_hz
    mix_c = 2.0 * signal * np.cos(w * t_s)
    mix_s = 2.0 * signal * np.sin(w * t_s)
    kernel = np.ones(period) / period
    c = np.convolve(mix_c, kernel, mode="valid")
    s = np.convolve(mix_s, kernel, mode="valid")
    t_center = np.convolve(t_s, kernel, mode="valid")
    return t_center, c, s
