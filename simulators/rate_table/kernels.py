"""Compiled (numba) per-block work of the table mechanics: the angle deviation handed to the
World (profile curvature, ripple, OU jitter) for a block, in one call instead of ~12 small numpy
operations."""

from __future__ import annotations

import math

import numpy as np

from bench.kernel_cache import njit  # NUMBA_CACHE_DIR keyed on the kernels' sources

_DEG = math.pi / 180.0


@njit(cache=True)
def deviation_rad(
    angles: np.ndarray,
    settled: bool,
    a0: float,
    rate_step_deg: float,
    mean_rate_dps: float,
    dt_s: float,
    ripple1_deg: float,
    ripple2_deg: float,
    w: np.ndarray,
    e: float,
    y_prev: float,
    out: np.ndarray,
    w_scale: float = 1.0,
) -> float:
    """out_k = radians(angle_k - a0 - mean_rate t_k + ripple(angle_k) + jitter_k) over the block,
    t_k = (k + 1) dt.  angle_k = a0 + rate_step_deg (k + 1) when `settled` (then `angles` is not
    read), else angles[k].  jitter_k = e jitter_(k-1) + w_k from jitter_(-1) = y_prev / e (an AR(1)
    / OU process; no jitter if w is empty), the innovations w_k taken as w[k] * w_scale (standard
    normals and their scale: the product numpy's w * w_scale gives).  Returns the last jitter."""
    y = y_prev
    noise = w.shape[0] > 0
    for k in range(out.shape[0]):
        s = float(k + 1)
        ang = a0 + rate_step_deg * s if settled else angles[k]
        th = ang * _DEG
        ripple = ripple1_deg * math.sin(th) + ripple2_deg * math.sin(2.0 * th)
        jitter = 0.0
        if noise:
            wk = w[k] * w_scale
            y = (y + wk) if k == 0 else (e * y + wk)
            jitter = y
        out[k] = (ang - a0 - mean_rate_dps * (dt_s * s) + ripple + jitter) * _DEG
    return y


@njit(cache=True)
def deviation_rad_blocks(
    a0_deg: np.ndarray,
    rate_step_deg: float,
    mean_rate_dps: np.ndarray,
    dt_s: float,
    ripple1_deg: float,
    ripple2_deg: float,
    w: np.ndarray,
    e: float,
    state: float,
    out: np.ndarray,
    w_scale: float,
) -> float:
    """`deviation_rad` of a settled table for K blocks of n samples (out (K, n)), block j from
    angle a0_deg[j] at mean rate mean_rate_dps[j], its jitter innovations w[j n:(j + 1) n] (w
    empty: no jitter) continuing from the jitter state as the per-block calls chain it (y_prev =
    e state).  Returns the last jitter (the new state)."""
    n = out.shape[1]
    noise = w.shape[0] > 0
    for j in range(out.shape[0]):
        wj = w[j * n : (j + 1) * n] if noise else w
        y_prev = e * state if noise else 0.0
        y = deviation_rad(wj[:0], True, a0_deg[j], rate_step_deg, mean_rate_dps[j], dt_s, ripple1_deg, ripple2_deg,
                          wj, e, y_prev, out[j], w_scale)  # fmt: skip
        if noise:
            state = y
    return state


@njit(cache=True)
def profile_step(
    state: np.ndarray,
    n: int,
    dt_s: float,
    alpha: float,
    halted: bool,
    mode: int,
    target_rate_dps: float,
    accel_dps2: float,
    brake_decel_dps2: float,
    traverse_dps: float,
    target_unwrapped_deg: float,
    watchdog_expired: bool,
    angles: np.ndarray,
) -> None:
    """TableMechanics' motion over n samples while it is not settled, sample by sample: the
    profile's velocity toward its goal within the acceleration, the lag (first order, alpha per
    sample) and the angle; angles[k] the angle at sample k's end.  state = (ref_dps, ref_angle_deg,
    rate_dps, angle_deg, position_done, enabled), updated in place; modes as
    drivers.rate_table.modbus_protocol (1 rate, 2 position).  The arithmetic of the Python loop it
    replaced, operation for operation."""
    ref, ref_angle, rate, angle = state[0], state[1], state[2], state[3]
    done, enabled = state[4] != 0.0, state[5] != 0.0
    for k in range(n):
        if halted or not enabled:
            goal, a = 0.0, brake_decel_dps2
        elif mode == 1:
            goal, a = target_rate_dps, accel_dps2
        elif mode == 2 and not done:
            a = accel_dps2
            err = target_unwrapped_deg - ref_angle
            v = min(traverse_dps, math.sqrt(2.0 * a * abs(err)), abs(err) / dt_s)
            goal = math.copysign(v, err)
        else:
            goal, a = 0.0, accel_dps2
        dv = a * dt_s
        ref_old = ref
        ref = goal if abs(goal - ref_old) <= dv else ref_old + math.copysign(dv, goal - ref_old)
        ref_angle += 0.5 * (ref_old + ref) * dt_s
        if mode == 2 and enabled and not done:
            err = target_unwrapped_deg - ref_angle
            if abs(err) <= 1e-9 or (abs(err) <= a * dt_s * dt_s and abs(ref) <= dv):
                ref_angle, ref, done = target_unwrapped_deg, 0.0, True
        y_old = rate
        y = y_old + (ref - y_old) * alpha
        if abs(y - ref) < 1e-9:
            y = ref
        rate = y
        angle += 0.5 * (y_old + y) * dt_s
        if watchdog_expired and enabled and y == 0.0 and ref == 0.0:
            enabled = False
        angles[k] = angle
    state[0], state[1], state[2], state[3] = ref, ref_angle, rate, angle
    state[4] = 1.0 if done else 0.0
    state[5] = 1.0 if enabled else 0.0
