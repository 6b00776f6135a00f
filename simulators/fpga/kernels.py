"""Compiled (numba) per-block work of the simulated FPGA: demodulate a block, update the loops,
boxcar-decimate and encode the stream.  The same arithmetic as the Python it replaced (orbit elements of the
block mean, PI loops with anti-windup, forces along d q / d a, d q / d k, d q / d theta), in one
call per block instead of ~40 small numpy operations.  Arrays of named slots carry the registers
(P_*) and the loop state (S_*) in and out.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from drivers.fpga.protocol import put_stream_frame

# loop parameters (registers), packed by FpgaFirmware when a register is written
P_AGC_SETPOINT, P_PLL_KI, P_PLL_KP, P_FORCE_LIMIT, P_AGC_KP, P_AGC_KI, P_DRIVE_FORCE = range(7)
P_QUAD_KP, P_QUAD_KI, P_PRECESSION_RATE_DPS, P_DRIFT_D_PER_S, P_DRIFT_THETA_TAU_DEG = range(7, 12)
PARAM_REGS = (
    "AGC_SETPOINT", "PLL_KI", "PLL_KP", "FORCE_LIMIT", "AGC_KP", "AGC_KI", "DRIVE_FORCE",
    "QUAD_KP", "QUAD_KI", "PRECESSION_RATE_DPS", "DRIFT_D_PER_S", "DRIFT_THETA_TAU_DEG",
)  # fmt: skip
# loop state
S_AGC_INT, S_QUAD_INT, S_PLL_INT_HZ, S_A, S_PHASE_ERR, S_PLL_FREQ_HZ = range(6)
S_U = 6  # 6..9: the force held over the next block
S_OUT = 10  # 10..13: amp, freq, quad, prec outputs (freq is set per block by before_block)
N_STATE = 14

# control bits (drivers.fpga.protocol), repeated here as compile-time constants
_DRIVE_EN, _AGC_EN, _PLL_EN, _QUAD_EN, _WHOLE_ANGLE, _DRIFT_COMP_EN = 0x01, 0x02, 0x04, 0x08, 0x10, 0x40


@njit(cache=True)
def _clamp(x: float, limit: float) -> float:
    return max(-limit, min(limit, x))


@njit(cache=True)
def update_loops(q_meas: np.ndarray, t_block_s: float, ctrl: int, prm: np.ndarray, st: np.ndarray) -> None:
    """The loops' update at the end of a block from the mean of its measured samples (n, 4)."""
    n = q_meas.shape[0]
    cx = sx = cy = sy = 0.0
    for i in range(n):
        cx += q_meas[i, 0]
        sx += q_meas[i, 1]
        cy += q_meas[i, 2]
        sy += q_meas[i, 3]
    cx /= n
    sx /= n
    cy /= n
    sy /= n
    # orbit elements (bench.analysis.slow_model.orbit_elements)
    e = cx * cx + sx * sx + cy * cy + sy * sy
    r = cx * cx + sx * sx - cy * cy - sy * sy
    s = 2.0 * (cx * cy + sx * sy)
    qq = 2.0 * (cx * sy - sx * cy)
    theta = 0.25 * math.atan2(s, r)
    a = math.sqrt(max(0.5 * (e + math.hypot(r, s)), 0.0))
    k = qq / (2.0 * a) if a > 0 else 0.0
    c2, s2 = math.cos(2 * theta), math.sin(2 * theta)
    chi = math.atan2(-(sx * c2 + sy * s2), cx * c2 + cy * s2)
    st[S_A] = a
    phase_err = (chi + 0.5 * math.pi) % math.pi - 0.5 * math.pi
    st[S_PHASE_ERR] = phase_err
    setpoint = prm[P_AGC_SETPOINT]
    if ctrl & _PLL_EN and a > 0.01 * max(setpoint, 1e-12):
        st[S_PLL_INT_HZ] += prm[P_PLL_KI] * phase_err * t_block_s
        st[S_PLL_FREQ_HZ] = st[S_PLL_INT_HZ] + prm[P_PLL_KP] * phase_err
    if not ctrl & _DRIVE_EN:
        return
    limit = prm[P_FORCE_LIMIT]
    weak = a < 0.01 * max(setpoint, 1e-12)
    if weak:  # no wave to lock onto yet: excite along the x pickoff axis, in phase
        theta, chi, k = 0.0, 0.0, 0.0
        c2, s2 = 1.0, 0.0
    cc, sc = math.cos(chi), math.sin(chi)
    if ctrl & _AGC_EN:
        err = setpoint - a
        f_a = prm[P_AGC_KP] * err + st[S_AGC_INT]
        if abs(f_a) < limit or f_a * err < 0:  # anti-windup: integrate only off the stop
            st[S_AGC_INT] += prm[P_AGC_KI] * err * t_block_s
        f_a = _clamp(f_a, limit)
    else:
        f_a = _clamp(prm[P_DRIVE_FORCE], limit)
    f_q = 0.0
    if ctrl & _QUAD_EN and not weak:
        f_q = -(prm[P_QUAD_KP] * k + st[S_QUAD_INT])
        if abs(f_q) < limit or f_q * k > 0:
            st[S_QUAD_INT] += prm[P_QUAD_KI] * k * t_block_s
        f_q = _clamp(f_q, limit)
    f_p = 0.0
    if ctrl & _WHOLE_ANGLE and not weak:
        f_p = 4.0 * a * math.radians(prm[P_PRECESSION_RATE_DPS])
        if ctrl & _DRIFT_COMP_EN:
            th_tau = math.radians(prm[P_DRIFT_THETA_TAU_DEG])
            f_p -= a * prm[P_DRIFT_D_PER_S] * math.sin(4.0 * (theta - th_tau))
        f_p = _clamp(f_p, limit)
    # u = f_a e_a + f_q e_k + f_p e_p with the unit forces along a, k and theta
    st[S_U + 0] = f_a * (c2 * cc) + f_q * (-s2 * sc) + f_p * (-s2 * cc)
    st[S_U + 1] = f_a * (-c2 * sc) + f_q * (-s2 * cc) + f_p * (s2 * sc)
    st[S_U + 2] = f_a * (s2 * cc) + f_q * (c2 * sc) + f_p * (c2 * cc)
    st[S_U + 3] = f_a * (-s2 * sc) + f_q * (c2 * cc) + f_p * (-c2 * sc)
    st[S_OUT + 0] = f_a
    st[S_OUT + 2] = f_q
    st[S_OUT + 3] = f_p


@njit(cache=True)
def emit_frames(
    q_meas: np.ndarray,
    i0: int,
    dt_s: float,
    dec: int,
    carry: np.ndarray,
    carry_n: int,
    outputs: np.ndarray,
    seq0: int,
    frames: np.ndarray,
    crc_table: np.ndarray,
    crc_zeros: int,
) -> tuple:
    """Encode a block's stream frames into `frames` (rows of 60 bytes, constant fields preset):
    samples i0, i0 + 1, ... (n, 4) decimated by `dec` with a boxcar (CIC-1) filter, i.e. a frame
    at every sample index divisible by dec carrying the mean of the `dec` samples ending there
    (the first frame also counts the `carry_n` samples summed in `carry` (4,) by the last block),
    and the loop outputs (4,).  Returns (frames written, new carry_n) and updates carry."""
    n = q_meas.shape[0]
    row = np.empty(8)
    for c in range(4):
        row[4 + c] = outputs[c]
    if dec <= 1:
        for i in range(n):
            for c in range(4):
                row[c] = q_meas[i, c]
            put_stream_frame(frames[i], seq0 + i, i0 + i, float(i0 + i) * dt_s, row, crc_table, crc_zeros)
        return n, carry_n
    c0, c1, c2, c3 = 0.0, 0.0, 0.0, 0.0
    p0, p1, p2, p3 = 0.0, 0.0, 0.0, 0.0
    k0, k1, k2, k3 = carry[0], carry[1], carry[2], carry[3]
    nf = 0
    nxt = (-i0) % dec
    last = -1 - carry_n
    for i in range(n):
        c0 += q_meas[i, 0]
        c1 += q_meas[i, 1]
        c2 += q_meas[i, 2]
        c3 += q_meas[i, 3]
        if i == nxt:
            e0, e1, e2, e3 = c0 + k0, c1 + k1, c2 + k2, c3 + k3
            count = i - last
            row[0] = (e0 - p0) / count
            row[1] = (e1 - p1) / count
            row[2] = (e2 - p2) / count
            row[3] = (e3 - p3) / count
            put_stream_frame(frames[nf], seq0 + nf, i0 + i, float(i0 + i) * dt_s, row, crc_table, crc_zeros)
            p0, p1, p2, p3 = e0, e1, e2, e3
            last = i
            nf += 1
            nxt += dec
    if nf:
        carry[0] = (c0 + k0) - p0
        carry[1] = (c1 + k1) - p1
        carry[2] = (c2 + k2) - p2
        carry[3] = (c3 + k3) - p3
        return nf, n - 1 - last
    carry[0] = c0 + k0
    carry[1] = c1 + k1
    carry[2] = c2 + k2
    carry[3] = c3 + k3
    return 0, n + carry_n
