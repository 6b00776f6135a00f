"""Compiled (numba) per-block work of the simulated FPGA: demodulate a block, update the loops,
rotate their forces onto the electrodes, boxcar-decimate and encode the stream.  Arrays of named
slots carry the registers (P_*) and the loop state (S_*) in and out.

The loops act in the wave's frame (forces f_a along d q / d a, f_q along d q / d k, f_p along
d q / d theta); `update_loops` estimates the wave (amplitude a, quadrature k, angle theta, phase
chi and the rates of theta and chi) from the mean of a block's samples, which is the wave at the
block's mean sample time, and updates the PI loops; `wave_force` then turns the wave-frame forces
into electrode forces at the angle and phase the wave is predicted to have at the middle of the
block they are held over.  Without that prediction a force held over a block acts along the
wave's direction one block period ago: while the wave turns at Omega, the amplitude force f_a then
leaks -f_a Omega T / (2 a) into dtheta/dt, a precession scale error of -gamma T / 2 (0.017 % at
50 ms blocks).  The precession force F_p turns the wave at F_p / (4 a) with a the amplitude while
the force is held, so F_p = 4 a Omega_cmd takes a predicted at the block's middle too (from its rate
between estimates): the damping anisotropy pumps the amplitude at 4 theta and the AGC follows it
with a lag, so an F_p from the block's estimate missed the command by (da/dt / a) x ~1.5 blocks,
with the damping drift's pattern: it read the drift 1.5 % low and left 0.37 deg/h of 4 theta after
compensation at 10 deg/s (0.013 now; benchmarks/wa_rate_drift.py).
The quadrature loop is a PI on k plus the split's pattern fed forward: a frequency
split pumps quadrature at a rate (d/a) = h_c cos 4 theta + h_s sin 4 theta fixed in the case frame,
which a PI in the wave's frame must follow as the wave turns and cannot (at 2 deg/s the 4 theta
pattern turns at 0.14 rad/s, under the PI's 1 rad/s): the k it leaves lags the pattern, and the
split turns that k into a drift -(Dw/2) (k/a) cos 4 (theta - theta_w) with a mean and an 8 theta
part (25 deg/h each, output-referred, for a 5 mHz split).  The observer measures the pumping
(dk/dt - f_q/2 between block estimates), fits (h_c, h_s) by exponentially weighted least squares
on the angle it was seen at, and `wave_force` cancels it at the predicted angle; the PI is left
with the rest.  At a fixed angle only one combination is seen; the other is learnt once the
wave turns (about 10 s at 2 deg/s).  The observer keeps its estimate over a drive cut (the
split is the resonator's) and starts afresh when the quadrature loop is switched on.  It learns
only while the amplitude is held (AGC_SETTLED_REL): while the AGC pushes the amplitude up its force
leaks into dk/dt, which read as pumping biased h by ~1 % and left -0.04 deg/h of mean drift in
hrg-damping's verification (docs/damping_drift.md).  It does not learn in force-to-rebalance
(the wave held at one angle: the PI's integrator takes the pumping there; docs/fpga_link.md).
"""

from __future__ import annotations

import math

import numpy as np

from bench.kernel_cache import njit  # NUMBA_CACHE_DIR keyed on the kernels' sources
from drivers.fpga.protocol import put_stream_frame

# loop parameters (registers), packed by FpgaFirmware when a register is written
P_AGC_SETPOINT, P_PLL_KI, P_PLL_KP, P_FORCE_LIMIT, P_AGC_KP, P_AGC_KI, P_DRIVE_FORCE = range(7)
P_QUAD_KP, P_QUAD_KI, P_PRECESSION_RATE_DPS, P_DRIFT_D_PER_S, P_DRIFT_THETA_TAU_DEG = range(7, 12)
P_OUTPUT_MODE, P_FTR_ANGLE_DEG, P_FTR_KP, P_FTR_KI, P_FTR_GAIN = range(12, 17)
P_FM_FORCE_HZ, P_FM_RATE_HZ = range(17, 19)
P_TRIM_BIAS_DPH, P_TRIM_BIAS_DPH_PER_HZ = 19, 20  # the thermal trim (0, 0 unless TRIM_EN has TRIM_THERMAL)
P_TRIM_SF_PPM, P_TRIM_SF_PPM_PER_HZ = 21, 22  # its scale factor part (0, 0 likewise)
# the hysteresis trim: the play's signed half-width (Hz; always in force: the play tracks), and the
# heating-minus-cooling bias and scale factor error its state multiplies (0, 0 unless TRIM_THERMAL)
P_TRIM_HYST_HZ, P_TRIM_BIAS_HYST_DPH, P_TRIM_SF_HYST_PPM = 23, 24, 25
PARAM_REGS = (
    "AGC_SETPOINT", "PLL_KI", "PLL_KP", "FORCE_LIMIT", "AGC_KP", "AGC_KI", "DRIVE_FORCE",
    "QUAD_KP", "QUAD_KI", "PRECESSION_RATE_DPS", "DRIFT_D_PER_S", "DRIFT_THETA_TAU_DEG",
    "OUTPUT_MODE", "FTR_ANGLE_DEG", "FTR_KP", "FTR_KI", "FTR_GAIN", "FM_FORCE_HZ", "FM_RATE_HZ",
    "TRIM_BIAS_DPH", "TRIM_BIAS_DPH_PER_HZ", "TRIM_SF_PPM", "TRIM_SF_PPM_PER_HZ",
    "TRIM_HYST_HZ", "TRIM_BIAS_HYST_DPH", "TRIM_SF_HYST_PPM",
)  # fmt: skip
# loop state
S_AGC_INT, S_QUAD_INT, S_PLL_INT_HZ, S_A, S_PHASE_ERR, S_PLL_FREQ_HZ = range(6)
S_U = 6  # 6..9: the force held over the block (set by wave_force)
S_OUT = 10  # 10..13: amp, freq, quad, prec outputs (freq is set per block by before_block)
# the wave estimate: valid flag (0 none, 1 angle and phase, 2 with rates), time of the estimate,
# theta and chi there, their rates (chi's relative to the reference of the block), the reference
# of the block, the block's end time, and the wave-frame forces without the compensation term
S_EST, S_T_EST, S_THETA, S_CHI, S_THETA_RATE, S_CHI_RATE, S_REF_HZ, S_T_END = range(14, 22)
S_WEAK, S_F_A, S_F_Q_P, S_F_P = range(22, 26)
# the split observer (case frame): the last block's k, applied f_q and length, whether it learned,
# the information matrix (m_cc, m_cs, m_ss), its right-hand side (v_c, v_s) and the estimate (h_c, h_s)
S_OBS_K, S_OBS_FQ, S_OBS_N, S_OBS_OK, S_M_CC, S_M_CS, S_M_SS, S_V_C, S_V_S, S_H_C, S_H_S = range(26, 37)
# the gyro's outputs: the rate output of the block (force-to-rebalance), the last frame's unwrapped
# angle and whether there is one (the unwrapping restarts with the stream), the rebalance integrator
S_RATE_OUT, S_ANGLE_OUT, S_ANGLE_OK, S_FTR_INT = range(37, 41)
S_SPAN = 41  # the span between the last two wave estimates (the rates' baseline)
# loop saturation (drivers.fpga.protocol SAT_*): the clamps the last update hit (S_SAT_NEXT), and
# those of the forces held over this block (S_SAT: that update's and wave_force's), streamed
S_SAT_NEXT, S_SAT = 42, 43
S_A_RATE = 44  # the amplitude's rate between the last two wave estimates (1/s x amplitude)
S_FW, S_FW_PREV = 45, 46  # the frequency-control force held over the last block and the one before
# the wave's phase acceleration (rad/s^2: 2 pi times its frequency's rate, e.g. on a temperature
# ramp) less the split pattern's, smoothed over CHI_ACC_TAU_S (wave_force's phase prediction)
S_CHI_ACC = 47
# the hysteresis play on the PLL frequency (update_play): its output (Hz, offset from REF_FREQ_HZ),
# whether it has one (0: it starts on the next frequency) and its normalised state s in [-1, +1]
S_PLAY_HZ, S_PLAY_OK, S_HYST = 48, 49, 50
N_STATE = 51
MODE_FTR = 1  # OUTPUT_MODE's force-to-rebalance (drivers.fpga.protocol.MODE_FORCE_TO_REBALANCE)
OBS_MEMORY_S = 100.0  # the observer forgets data older than this (exponential weight)
AGC_SETTLED_REL = 0.01  # the amplitude's band around the setpoint in which the split observer learns
OBS_RIDGE = 0.05**3  # damping of the solve: one 50 ms block's weight (weights are span^3: 1/variance)
CHI_ACC_TAU_S = 0.5  # smoothing of the phase acceleration (its lag; 2 s left 1700 deg/h per Hz/s on a ramp)

# control bits (drivers.fpga.protocol), repeated here as compile-time constants
_DRIVE_EN, _AGC_EN, _PLL_EN, _QUAD_EN, _WHOLE_ANGLE, _DRIFT_COMP_EN = 0x01, 0x02, 0x04, 0x08, 0x10, 0x40
_SAT_AMP, _SAT_QUAD, _SAT_PREC, _SAT_FTR = 0x1, 0x2, 0x4, 0x8  # drivers.fpga.protocol SAT_*


@njit(cache=True)
def _clamp(x: float, limit: float) -> float:
    return max(-limit, min(limit, x))


@njit(cache=True)
def _wrap(x: float, period: float) -> float:
    """x modulo period, in [-period/2, period/2)."""
    return (x + 0.5 * period) % period - 0.5 * period


@njit(cache=True)
def _observe_split(
    st: np.ndarray, k_rel: float, a: float, theta: float, span: float, n: int, dt_s: float, a_rel: float
) -> None:
    """One step of the split observer: the quadrature pumping d/a = (dk/dt - f_q/2) / a between the
    last block's estimate and this one's, regressed (exponentially weighted least squares) on
    cos 4 theta, sin 4 theta at the midpoint angle: the case-frame pattern h_c cos 4 theta + h_s sin 4 theta."""
    # f_q held over the last block from its mean sample time to its end, then this block's up to now
    n_prev = st[S_OBS_N]
    f_int = st[S_OBS_FQ] * 0.5 * (n_prev - 1) * dt_s + (st[S_OUT + 2] / a) * 0.5 * (n + 1) * dt_s
    y = (k_rel - st[S_OBS_K] - 0.5 * f_int) / span
    th_m = st[S_THETA] + 0.5 * _wrap(theta - st[S_THETA], 0.5 * math.pi)
    c4, s4 = math.cos(4.0 * th_m), math.sin(4.0 * th_m)
    lam = math.exp(-span / OBS_MEMORY_S)
    w = span * span * span * min(a_rel * a_rel, 1.0)  # 1/variance: k/a's noise goes as 1/a, its slope's as span^-3/2
    st[S_M_CC] = lam * st[S_M_CC] + w * c4 * c4
    st[S_M_CS] = lam * st[S_M_CS] + w * c4 * s4
    st[S_M_SS] = lam * st[S_M_SS] + w * s4 * s4
    st[S_V_C] = lam * st[S_V_C] + w * c4 * y
    st[S_V_S] = lam * st[S_V_S] + w * s4 * y
    st[S_H_C], st[S_H_S] = solve_split(st[S_M_CC], st[S_M_CS], st[S_M_SS], st[S_V_C], st[S_V_S])


@njit(cache=True)
def solve_split(m_cc: float, m_cs: float, m_ss: float, v_c: float, v_s: float) -> tuple:
    """The pattern h of the normal equations M h = v, damped: (M^2 + r^2) h = M v.  A direction
    the data have seen (eigenvalue m >> r) is solved exactly (relative bias (r/m)^2, 1e-6 after
    ~100 s of data); an unseen one (m << r: the wave has not turned yet) stays near 0.  A ridge
    (M + r) h = v would shrink every direction by r/m (0.1 % with 100 s of memory): the pumping
    left over turns with the wave, the quadrature loop lags it and the split turns that lag into a
    drift proportional to the rate (a 0.4 ppm scale error at 5 mHz)."""
    r2 = OBS_RIDGE * OBS_RIDGE
    a_cc = m_cc * m_cc + m_cs * m_cs + r2
    a_cs = m_cs * (m_cc + m_ss)
    a_ss = m_cs * m_cs + m_ss * m_ss + r2
    b_c = m_cc * v_c + m_cs * v_s
    b_s = m_cs * v_c + m_ss * v_s
    det = a_cc * a_ss - a_cs * a_cs
    return (a_ss * b_c - a_cs * b_s) / det, (a_cc * b_s - a_cs * b_c) / det


@njit(cache=True)
def _split_freq(st: np.ndarray, theta: float) -> float:
    """The split's part of the wave's frequency (rad/s of chi) at angle theta: p'(theta) / 4 of the
    observer's pumping pattern p (split_phase)."""
    return st[S_H_S] * math.cos(4.0 * theta) - st[S_H_C] * math.sin(4.0 * theta)


@njit(cache=True)
def _update_chi_acc(
    st: np.ndarray, theta: float, chi_rate: float, span: float, ref_hz: float, ctrl: int, prm: np.ndarray
) -> None:
    """Smooth the wave's phase acceleration from the change of chi's rate between the last two
    spans (each relative to its block's reference: the reference's step added back), less the
    split pattern's change as the wave turned (split_phase predicts that part).  A moving
    frequency (a temperature ramp: 2 pi df/dt) otherwise leaves the predicted phase behind by
    2 pi (df/dt) T^2 at T-long blocks, and the quadrature force, applied at that phase, leaks into
    the rebalance force: 21 000 deg/h per Hz/s on sim-mems-thermal (docs/chamber.md).  None while
    the frequency-control force moves chi (its own term in wave_force)."""
    if st[S_EST] < 2 or (prm[P_FM_FORCE_HZ] > 0.0 and prm[P_FM_RATE_HZ] > 0.0):
        st[S_CHI_ACC] = 0.0
        return
    d_rate = chi_rate - st[S_CHI_RATE] + 2.0 * math.pi * (ref_hz - st[S_REF_HZ])
    if ctrl & _QUAD_EN:  # the pattern at this span's midpoint angle and at the last one's
        th_now = st[S_THETA] + 0.5 * _wrap(theta - st[S_THETA], 0.5 * math.pi)
        th_last = st[S_THETA] - 0.5 * st[S_THETA_RATE] * st[S_SPAN]
        d_rate -= _split_freq(st, th_now) - _split_freq(st, th_last)
    acc = d_rate / (0.5 * (span + st[S_SPAN]))
    st[S_CHI_ACC] += min(span / CHI_ACC_TAU_S, 1.0) * (acc - st[S_CHI_ACC])


@njit(cache=True)
def update_loops(
    q_meas: np.ndarray, t_end_s: float, dt_s: float, ref_hz: float, ctrl: int, prm: np.ndarray, st: np.ndarray
) -> None:
    """The loops' update at the end of a block of measured samples (n, 4) whose last sample is at
    t_end_s, taken with the reference at ref_hz: the wave estimate from the block mean (the wave
    at the mean sample time), the PLL and the wave-frame forces for the next block."""
    n = q_meas.shape[0]
    t_block_s = n * dt_s
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
    a_prev = st[S_A]
    st[S_A] = a
    phase_err = (chi + 0.5 * math.pi) % math.pi - 0.5 * math.pi
    st[S_PHASE_ERR] = phase_err
    setpoint = prm[P_AGC_SETPOINT]
    weak = a < 0.01 * max(setpoint, 1e-12)
    # the wave estimate and its rates (from the last block's, when that block came just before)
    t_est = t_end_s - 0.5 * (n - 1) * dt_s
    t_start = t_end_s - t_block_s
    quad_on = ctrl & _QUAD_EN and ctrl & _DRIVE_EN and not weak
    if weak:
        st[S_EST] = st[S_CHI_ACC] = 0.0
    else:
        if st[S_EST] > 0 and abs(st[S_T_END] - t_start) < 0.5 * dt_s and t_est > st[S_T_EST]:
            span = t_est - st[S_T_EST]
            # the observer learns while the amplitude is held (AGC within AGC_SETTLED_REL of its
            # setpoint, or the AGC off): an AGC pushing the amplitude up leaks into dk/dt
            settled = not ctrl & _AGC_EN or abs(a - setpoint) <= AGC_SETTLED_REL * setpoint
            # nor in force-to-rebalance: the held wave shows one combination only, and with it the
            # rebalance force's leak into quadrature through the readout phase delay, which follows
            # the input rate; learnt over the observer's memory it left k = 2 (dh/dt) / QUAD_KI after
            # each rate change, which the split turned into a scale error (docs/fpga_link.md)
            if quad_on and st[S_OBS_OK] > 0 and settled and prm[P_OUTPUT_MODE] != MODE_FTR:
                _observe_split(st, k / a, a, theta, span, n, dt_s, a / max(setpoint, 1e-12))
            # chi is relative to the reference: add back the reference's change since the last estimate
            d_chi = _wrap(chi - st[S_CHI], math.pi) + 2.0 * math.pi * (st[S_REF_HZ] - ref_hz) * (t_start - st[S_T_EST])
            _update_chi_acc(st, theta, d_chi / span, span, ref_hz, ctrl, prm)  # before the rates move on
            st[S_THETA_RATE] = _wrap(theta - st[S_THETA], 0.5 * math.pi) / span
            st[S_CHI_RATE] = d_chi / span
            st[S_A_RATE] = (a - a_prev) / span
            st[S_SPAN] = span
            st[S_EST] = 2.0
        else:
            st[S_THETA_RATE] = st[S_CHI_RATE] = st[S_A_RATE] = st[S_CHI_ACC] = 0.0
            st[S_EST] = 1.0
        st[S_THETA] = theta
        st[S_CHI] = chi
        st[S_T_EST] = t_est
        st[S_REF_HZ] = ref_hz
    st[S_T_END] = t_end_s
    st[S_OBS_OK] = 1.0 if quad_on else 0.0
    st[S_OBS_K] = k / a if a > 0 else 0.0
    st[S_OBS_FQ] = st[S_OUT + 2] / a if a > 0 else 0.0  # the quadrature force held over this block
    st[S_OBS_N] = n
    if ctrl & _PLL_EN and a > 0.01 * max(setpoint, 1e-12):
        st[S_PLL_INT_HZ] += prm[P_PLL_KI] * phase_err * t_block_s
        st[S_PLL_FREQ_HZ] = st[S_PLL_INT_HZ] + prm[P_PLL_KP] * phase_err
    st[S_SAT_NEXT] = 0.0
    if not ctrl & _DRIVE_EN:
        return
    limit = prm[P_FORCE_LIMIT]
    sat = 0
    st[S_WEAK] = 1.0 if weak else 0.0
    if ctrl & _AGC_EN:
        err = setpoint - a
        f_a = prm[P_AGC_KP] * err + st[S_AGC_INT]
        if abs(f_a) < limit or f_a * err < 0:  # anti-windup: integrate only off the stop
            st[S_AGC_INT] += prm[P_AGC_KI] * err * t_block_s
    else:
        f_a = prm[P_DRIVE_FORCE]
    if abs(f_a) > limit:
        sat |= _SAT_AMP
    f_a = _clamp(f_a, limit)
    f_q = 0.0
    if ctrl & _QUAD_EN and not weak:
        f_q = -(prm[P_QUAD_KP] * k + st[S_QUAD_INT])
        if abs(f_q) < limit or f_q * k > 0:
            st[S_QUAD_INT] += prm[P_QUAD_KI] * k * t_block_s
        if abs(f_q) > limit:
            sat |= _SAT_QUAD
        f_q = _clamp(f_q, limit)
    f_p = 0.0
    if prm[P_OUTPUT_MODE] == MODE_FTR:
        if not weak:  # rebalance: a PI on the angle error commands the wave's rate u; F_p = 4 a u
            err = _wrap(theta - math.radians(prm[P_FTR_ANGLE_DEG]), 0.5 * math.pi)
            f_p = -4.0 * a * (prm[P_FTR_KP] * err + st[S_FTR_INT])
            if abs(f_p) < limit or f_p * err > 0:  # anti-windup: integrate only off the stop
                st[S_FTR_INT] += prm[P_FTR_KI] * err * t_block_s
            if abs(f_p) > limit:
                sat |= _SAT_FTR
            f_p = _clamp(f_p, limit)
    elif ctrl & _WHOLE_ANGLE and not weak:
        f_p = 4.0 * a * math.radians(prm[P_PRECESSION_RATE_DPS])
    st[S_F_A] = f_a
    st[S_F_Q_P] = f_q
    st[S_F_P] = f_p
    st[S_SAT_NEXT] = sat


@njit(cache=True)
def split_phase(st: np.ndarray, t_mid: float) -> float:
    """The split's part of the wave's phase at t_mid that a constant-rate extrapolation of chi
    from the last estimate misses.  A split makes the wave's frequency depend on its angle:
    w = w_mean + g(theta), g = h_s cos 4 theta - h_c sin 4 theta = p'(theta) / 4 with p the
    observer's pumping pattern; the measured rate of chi is g's mean over the last span (around
    theta(t_est - span / 2)), while chi moves on with g's mean up to t_mid (around
    theta(t_est + dt / 2))."""
    span = st[S_SPAN]
    dt_pred = t_mid - st[S_T_EST]
    th_m = st[S_THETA] - 0.5 * st[S_THETA_RATE] * span
    th_q = st[S_THETA] + 0.5 * st[S_THETA_RATE] * dt_pred
    g_q = st[S_H_S] * math.cos(4.0 * th_q) - st[S_H_C] * math.sin(4.0 * th_q)
    g_m = st[S_H_S] * math.cos(4.0 * th_m) - st[S_H_C] * math.sin(4.0 * th_m)
    return (g_q - g_m) * dt_pred


@njit(cache=True)
def update_play(prm: np.ndarray, st: np.ndarray) -> None:
    """The hysteresis trim's play (backlash) on the PLL frequency's offset f (st[S_OUT + 1]): its output
    y moves only when |f - y| would exceed the half-width |h| (h = P_TRIM_HYST_HZ, signed as the
    frequency's temperature coefficient); S_HYST = (f - y) / h, +1 after heating, -1 after cooling, 0
    at the start (y = f) and with h = 0.  The frequency lags the resonator's temperature by nothing, so
    this is the package's play in temperature seen through df/dT (docs/fpga_link.md)."""
    h = prm[P_TRIM_HYST_HZ]
    f = st[S_OUT + 1]
    if h == 0.0:
        st[S_PLAY_OK] = 0.0
        st[S_HYST] = 0.0
        return
    if st[S_PLAY_OK] <= 0.0:
        st[S_PLAY_HZ] = f
        st[S_PLAY_OK] = 1.0
    w = abs(h)
    st[S_PLAY_HZ] = min(max(st[S_PLAY_HZ], f - w), f + w)
    st[S_HYST] = (f - st[S_PLAY_HZ]) / h


@njit(cache=True)
def wave_force(
    t_start_s: float, n: int, dt_s: float, ref_hz: float, ctrl: int, prm: np.ndarray, st: np.ndarray
) -> None:
    """The electrode force u (S_U) held over the block of n samples from t_start_s, with the
    reference at ref_hz: the wave-frame forces of the last update along the wave as predicted at
    the block's middle (angle and phase extrapolated at their measured rates), the drift
    compensation evaluated there too; the outputs amp, quad, prec (S_OUT) are these forces."""
    update_play(prm, st)
    limit = prm[P_FORCE_LIMIT]
    f_a, f_q, f_p = st[S_F_A], st[S_F_Q_P], st[S_F_P]
    f_w = 0.0
    st[S_RATE_OUT] = 0.0
    if abs(st[S_T_END] - t_start_s) >= 0.5 * dt_s:  # no update from the block just before (a drive cut)
        st[S_U : S_U + 4] = 0.0
        st[S_OUT + 0] = st[S_OUT + 2] = st[S_OUT + 3] = 0.0
        st[S_SAT] = 0.0
        st[S_FW] = st[S_FW_PREV] = 0.0
        return
    sat = int(st[S_SAT_NEXT])
    ftr = prm[P_OUTPUT_MODE] == MODE_FTR
    if st[S_WEAK] > 0 or st[S_EST] <= 0:  # no wave to lock onto yet: excite along the x pickoff axis, in phase
        theta, chi, f_q, f_p = 0.0, 0.0, 0.0, 0.0
    else:
        t_mid = t_start_s + 0.5 * n * dt_s
        theta = st[S_THETA] + st[S_THETA_RATE] * (t_mid - st[S_T_EST])
        # chi turns at its measured rate relative to the reference of the estimate's block, and
        # the reference of this block differs by (ref_hz - S_REF_HZ) from t_start on
        chi = st[S_CHI] + st[S_CHI_RATE] * (t_mid - st[S_T_EST]) + 2.0 * math.pi * (st[S_REF_HZ] - ref_hz) * (
            t_mid - t_start_s
        )
        if ctrl & _QUAD_EN and st[S_EST] > 1:  # the split's frequency pattern turning with the wave
            chi += split_phase(st, t_mid)
        if st[S_EST] > 1:
            # a moving frequency: chi's measured rate is its rate at the middle of the last span, half
            # a span before the estimate; from there to t_mid the phase gains acc x dt (span + dt) / 2
            dt_pred = t_mid - st[S_T_EST]
            chi += 0.5 * st[S_CHI_ACC] * dt_pred * (st[S_SPAN] + dt_pred)
        # the wave turns at F_p / (4 a) with a its amplitude while the force is held: F_p is the
        # command times the amplitude predicted at the block's middle, not the one estimated there
        a_mid = st[S_A] + st[S_A_RATE] * (t_mid - st[S_T_EST])
        if prm[P_FM_FORCE_HZ] > 0.0 and prm[P_FM_RATE_HZ] > 0.0:
            # the frequency-control force: along d q / d chi, f_w moves chi at f_w / (2 a), so
            # 4 pi a F moves the frequency by F Hz (times the chains' gains: what the FM measures)
            sq = 1.0 if math.sin(2.0 * math.pi * prm[P_FM_RATE_HZ] * t_mid) >= 0.0 else -1.0
            f_w = _clamp(4.0 * math.pi * a_mid * prm[P_FM_FORCE_HZ] * sq, limit)
        if st[S_EST] > 1 and st[S_A] > 0:
            # chi's measured rate is the force of the last two blocks' (f_prev + f_last) / (4 a); from
            # the estimate to t_mid it moves with (f_last + f_w) / (4 a): a switch of the square
            # wave would otherwise leave chi behind for a block and turn f_w partly into f_a
            chi += (f_w - st[S_FW_PREV]) / (4.0 * st[S_A]) * (t_mid - st[S_T_EST])
        if not ftr and st[S_A] > 0:
            f_p *= a_mid / st[S_A]
        if ctrl & _WHOLE_ANGLE and ctrl & _DRIFT_COMP_EN and not ftr:
            th_tau = math.radians(prm[P_DRIFT_THETA_TAU_DEG])
            f_p -= a_mid * prm[P_DRIFT_D_PER_S] * math.sin(4.0 * (theta - th_tau))
        # a turning wave: the block mean shrinks the amplitude estimate by s1 and a force held in
        # one direction pushes along the turning wave by s2 on average (both 1 - (Omega T)^2 / 6)
        x = st[S_THETA_RATE] * dt_s
        n_est = st[S_OBS_N]
        s1 = math.sin(n_est * x) / (n_est * math.sin(x)) if x != 0.0 and n_est > 0 else 1.0
        s2 = math.sin(n * x) / (n * x) if x != 0.0 else 1.0
        if not ftr:  # the rebalance force is the loop's own (its integrator absorbs any such factor)
            f_p = f_p / (s1 * s2)
            if abs(f_p) > limit:
                sat |= _SAT_PREC
            f_p = _clamp(f_p, limit)
        if ctrl & _QUAD_EN:  # cancel the split's quadrature pumping at the predicted angle
            c4, s4 = math.cos(4.0 * theta), math.sin(4.0 * theta)
            f_q = f_q - 2.0 * st[S_A] * (st[S_H_C] * c4 + st[S_H_S] * s4)
            if abs(f_q) > limit:
                sat |= _SAT_QUAD
            f_q = _clamp(f_q, limit)
    st[S_SAT] = sat
    st[S_FW_PREV] = st[S_FW]
    st[S_FW] = f_w
    c2, s2 = math.cos(2 * theta), math.sin(2 * theta)
    cc, sc = math.cos(chi), math.sin(chi)
    f_pu = f_p
    if f_w != 0.0:
        # the frequency-control force along d q / d chi of the measured orbit (a, k): (d q / d chi) / a
        # = e_chi + (k / a) e_p.  Along e_chi alone it would turn a wave with quadrature k at
        # -k f_w / (4 a^2), and the quadrature the force's own leak through skewed forcers pumps
        # (the loop nulls it a step late) would rectify into a drift ~ F^2 s_s cos 4 theta
        # (docs/readout_phase.md section 3)
        f_pu = f_p + f_w * st[S_OBS_K]
    # u = f_a e_a + f_q e_k + f_p e_p + f_w e_chi with the unit forces along a, k, theta and chi
    st[S_U + 0] = f_a * (c2 * cc) + f_q * (-s2 * sc) + f_pu * (-s2 * cc) + f_w * (-c2 * sc)
    st[S_U + 1] = f_a * (-c2 * sc) + f_q * (-s2 * cc) + f_pu * (s2 * sc) + f_w * (-c2 * cc)
    st[S_U + 2] = f_a * (s2 * cc) + f_q * (c2 * sc) + f_pu * (c2 * cc) + f_w * (-s2 * sc)
    st[S_U + 3] = f_a * (-s2 * sc) + f_q * (c2 * cc) + f_pu * (-c2 * sc) + f_w * (-s2 * cc)
    st[S_OUT + 0] = f_a
    st[S_OUT + 2] = f_q
    st[S_OUT + 3] = f_p
    if ftr and prm[P_AGC_SETPOINT] > 0:  # the rate output: G degrees(F_p / (4 a_set)), ratiometric,
        # less the thermal trim's bias at the PLL frequency (st[S_OUT + 1]: its offset from REF_FREQ_HZ),
        # over 1 + the thermal trim's scale factor error there (ppm; 0 off: the same numbers); the
        # hysteresis trim's halves times the play's state join both (heating minus cooling: s = +1 heating)
        trim_dph = (prm[P_TRIM_BIAS_DPH] + prm[P_TRIM_BIAS_DPH_PER_HZ] * st[S_OUT + 1]
                    + 0.5 * prm[P_TRIM_BIAS_HYST_DPH] * st[S_HYST])
        rate = prm[P_FTR_GAIN] * math.degrees(f_p / (4.0 * prm[P_AGC_SETPOINT])) - trim_dph / 3600.0
        sf_ppm = (prm[P_TRIM_SF_PPM] + prm[P_TRIM_SF_PPM_PER_HZ] * st[S_OUT + 1]
                  + 0.5 * prm[P_TRIM_SF_HYST_PPM] * st[S_HYST])
        if sf_ppm != 0.0:
            rate = rate / (1.0 + 1e-6 * sf_ppm)
        st[S_RATE_OUT] = rate


@njit(cache=True)
def _angle_out(row: np.ndarray, st: np.ndarray) -> None:
    """row[8] = the wave angle (deg) of the frame's pickoffs row[0:4], unwrapped against the last
    frame's (a quarter turn of the wave is one period of 4 theta: it must turn under 45 deg a frame)."""
    cx, sx, cy, sy = row[0], row[1], row[2], row[3]
    th = math.degrees(0.25 * math.atan2(2.0 * (cx * cy + sx * sy), cx * cx + sx * sx - cy * cy - sy * sy))
    if st[S_ANGLE_OK] > 0:
        th = st[S_ANGLE_OUT] + _wrap(th - st[S_ANGLE_OUT], 90.0)
    st[S_ANGLE_OUT] = th
    st[S_ANGLE_OK] = 1.0
    row[8] = th


@njit(cache=True)
def emit_frames(
    q_meas: np.ndarray,
    i0: int,
    dt_s: float,
    dec: int,
    carry: np.ndarray,
    carry_n: int,
    st: np.ndarray,
    seq0: int,
    frames: np.ndarray,
    crc_table: np.ndarray,
    crc_zeros: int,
) -> tuple:
    """Encode a block's stream frames into `frames` (rows of 72 bytes, constant fields preset):
    samples i0, i0 + 1, ... (n, 4) decimated by `dec` with a boxcar (CIC-1) filter, i.e. a frame
    at every sample index divisible by dec carrying the mean of the `dec` samples ending there
    (the first frame also counts the `carry_n` samples summed in `carry` (4,) by the last block),
    the loop outputs (S_OUT of the loop state `st`), the wave angle of the frame's pickoffs unwrapped
    against the last frame's (S_ANGLE_OUT) and the rate output (S_RATE_OUT).  Returns (frames
    written, new carry_n) and updates carry."""
    n = q_meas.shape[0]
    row = np.empty(11)
    for c in range(4):
        row[4 + c] = st[S_OUT + c]
    row[9] = st[S_RATE_OUT]
    row[10] = st[S_SAT]
    if dec <= 1:
        for i in range(n):
            for c in range(4):
                row[c] = q_meas[i, c]
            _angle_out(row, st)
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
            _angle_out(row, st)
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


@njit(cache=True)
def after_block(
    q_meas: np.ndarray,
    update: bool,
    t_end_s: float,
    dt_s: float,
    ref_hz: float,
    ctrl: int,
    prm: np.ndarray,
    st: np.ndarray,
    stream: bool,
    i0: int,
    dec: int,
    carry: np.ndarray,
    carry_n: int,
    seq0: int,
    frames: np.ndarray,
    crc_table: np.ndarray,
    crc_zeros: int,
) -> tuple:
    """A block's firmware work in one compiled call: `update_loops` (with `update`), then
    `emit_frames` (with `stream`; else no frames, carry_n kept).  Returns (frames, new carry_n)."""
    if update:
        update_loops(q_meas, t_end_s, dt_s, ref_hz, ctrl, prm, st)
    if stream:
        return emit_frames(q_meas, i0, dt_s, dec, carry, carry_n, st, seq0, frames, crc_table, crc_zeros)
    return 0, carry_n


@njit(cache=True)
def turn_back(q: np.ndarray, cpx: float, spx: float, cpy: float, spy: float, out: np.ndarray) -> None:
    """out (n, 4) = the states q (n, 4) with each chain's (c, s) turned back by its phase trim
    (c = c' cos p + s' sin p, s = -c' sin p + s' cos p): the readout phase trim of `after_block`'s
    input, the same operations in the same order as the numpy form it replaced (firmware._turn_back)."""
    for i in range(q.shape[0]):
        c, s = q[i, 0], q[i, 1]
        out[i, 0] = c * cpx + s * spx
        out[i, 1] = -c * spx + s * cpx
        c, s = q[i, 2], q[i, 3]
        out[i, 2] = c * cpy + s * spy
        out[i, 3] = -c * spy + s * cpy
