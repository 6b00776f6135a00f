"""Compiled core of the world's fused blocks (simulators.fused): K blocks of the FPGA firmware's
loops closed around the linear resonator in one call, each block exactly as the per-block path
computes it (firmware before_block, the resonator's exact step, firmware after_block), in the
same order of floating-point operations, so a seeded run gives the same arrays bit for bit.

numba's cache keys a compiled function on its own file only: the firmware kernels it inlines
(simulators.fpga.kernels, drivers.fpga.protocol.put_stream_frame) are not watched by numba, so
the cache directory itself is keyed on a hash of every kernel source (bench.kernel_cache)."""

from __future__ import annotations

import numpy as np

from bench.kernel_cache import njit  # NUMBA_CACHE_DIR keyed on the kernels' sources
from simulators.fpga import kernels as fk
from simulators.physics.errors_kernel import pickoff_block
from simulators.physics.kernels import linear_block
from simulators.physics.params import TWO_PI

_SEQ_MOD = 1 << 32  # drivers.fpga.protocol.SEQ_MOD


@njit(cache=True)
def closed_loop_blocks(
    n: int,
    i0: int,
    dt: float,
    rate_rad_s: np.ndarray,  # (K,) input rate of each block (case rate + environment)
    ripple: np.ndarray,  # (K, n) the table's in-block angle deviation (rad), or (K, 0) for none
    zg: np.ndarray,  # the resonator's parameter vector (zg[1] set per block)
    four_k: float,
    nu_offset: float,
    w0: float,
    q: np.ndarray,  # resonator state, advanced
    psi_per_rad: float,
    sigma: float,
    slow: bool,  # the environment's slow drifts: per block zg[2], zg[3] and the pickoff gains below
    zg2: np.ndarray,
    zg3: np.ndarray,
    gain_x: np.ndarray,
    gain_y: np.ndarray,
    errs: bool,  # error sources (World.errors): the forcers' and the pickoff chains' below
    zg0: np.ndarray,  # (K,) per block zg[0], zg[4] at the unit's temperature, or (0,) for none
    zg4: np.ndarray,
    forcer: np.ndarray,  # (6,) ErrorSources._forcer_constants
    pickoff: np.ndarray,  # (12,) ErrorSources._pickoff_constants (flags as 0.0 / 1.0)
    pick_gx: np.ndarray,  # (K,) per block the pickoff chains' gains (ErrorSources.pickoff_gains)
    pick_gy: np.ndarray,
    q_true: np.ndarray,  # (K n, 4) out: true states
    q_meas: np.ndarray,  # (K n, 4) in: standard normals (sigma != 0); out: measured states
    drive: bool,  # DRIVE_EN: wave_force each block (else no force: the drive is off and cut)
    ref_follows: bool,  # the NCO sets the world's reference each block (active or owning it)
    ref_other_hz: float,  # the reference when it does not
    pll0_hz: float,  # PLL_FREQ_HZ at the first block
    ref_reg_hz: float,  # REF_FREQ_HZ
    update: bool,
    stream: bool,
    ctrl: int,
    prm: np.ndarray,
    st: np.ndarray,
    gains: np.ndarray,  # (4,) pickoff gain trims, or (0,) for none
    dec: int,
    carry: np.ndarray,
    carry_n: int,
    seq0: int,
    frames: np.ndarray,  # (>= K n, 72) uint8 stream frame buffer
    crc_table: np.ndarray,
    crc_zeros: int,
    frame_counts: np.ndarray,  # (K,) out: frames written by each block (consecutive in `frames`)
    ref_hz: np.ndarray,  # (K,) out: the world's reference over each block
    force: np.ndarray,  # (4,) out: the force of the last block (the world's held copy)
) -> tuple:
    """Returns (PLL_FREQ_HZ after the last block, the decimator's carry_n, stream seq after)."""
    k_blocks = rate_rad_s.shape[0]
    u = np.zeros(4)
    pll = pll0_hz
    seq = seq0
    off = 0
    scaled = np.empty((n, 4)) if gains.shape[0] > 0 else np.empty((0, 4))
    no_noise = np.empty((0, 4))
    uf = np.zeros(4)  # the force the modes receive (ErrorSources.force of u)
    thermal = zg0.shape[0] > 0
    for j in range(k_blocks):
        a = j * n
        t0 = (i0 + a) * dt
        # firmware before_block (no FM in a fused run: fm = 0.0 as there)
        ref = pll + 0.0 if ref_follows else ref_other_hz
        ref_hz[j] = ref
        st[fk.S_OUT + 1] = pll + 0.0 - ref_reg_hz
        if drive:
            fk.wave_force(t0, n, dt, ref, ctrl, prm, st)
            for i in range(4):
                u[i] = st[fk.S_U + i]
        uk = u
        if errs:  # ErrorSources.force, the same operations in the same order
            fgx, fgy, c_x, s_x, c_y, s_y = forcer[0], forcer[1], forcer[2], forcer[3], forcer[4], forcer[5]
            fx1, fx2, fy1, fy2 = fgx * u[0], fgx * u[1], fgy * u[2], fgy * u[3]
            uf[0] = c_x * fx1 - s_y * fy1
            uf[1] = c_x * fx2 - s_y * fy2
            uf[2] = s_x * fx1 + c_y * fy1
            uf[3] = s_x * fx2 + c_y * fy2
            uk = uf
        if thermal:  # Resonator.set_thermal
            zg[0], zg[4] = zg0[j], zg4[j]
        # the resonator's block (Resonator._linear_block)
        gx, gy = 1.0, 1.0
        if slow:
            zg[2], zg[3] = zg2[j], zg3[j]
            gx, gy = gain_x[j], gain_y[j]
        zg[1] = four_k * rate_rad_s[j] + nu_offset
        lam = TWO_PI * ref - w0
        out = q_true[a : a + n]
        meas = q_meas[a : a + n]
        if sigma != 0.0:
            linear_block(zg, lam, dt, q, uk, ripple[j], psi_per_rad, out, meas, sigma, gx, gy)
        else:
            linear_block(zg, lam, dt, q, uk, ripple[j], psi_per_rad, out, no_noise, sigma, 1.0, 1.0)
            for r in range(n):  # meas[:, :] = out, without the array assignment's compiled shape check
                for c in range(4):
                    meas[r, c] = out[r, c]
            if slow:  # Resonator._scale: X gains on cx, sx; Y on cy, sy
                for r in range(n):
                    meas[r, 0] *= gx
                    meas[r, 1] *= gx
                    meas[r, 2] *= gy
                    meas[r, 3] *= gy
        if errs:  # ErrorSources.measure (in place: each row is read before it is written)
            pickoff_block(
                meas, pickoff[0] != 0.0, pickoff[1], pickoff[2], pickoff[3], pickoff[4], pickoff[5],
                pickoff[6] != 0.0, pickoff[7], pickoff[8], pickoff[9] != 0.0, pickoff[10], pickoff[11],
                pick_gx[j], pick_gy[j], meas,
            )  # fmt: skip
        # firmware after_block
        fw_meas = meas
        if gains.shape[0] > 0:
            for r in range(n):
                for c in range(4):
                    scaled[r, c] = meas[r, c] * gains[c]
            fw_meas = scaled
        last = i0 + a + n
        if update:
            st[fk.S_PLL_FREQ_HZ] = pll
        nf, carry_n = fk.after_block(
            fw_meas, update, last * dt, dt, ref, ctrl, prm, st,
            stream, i0 + a + 1, dec, carry, carry_n, seq, frames[off:],
            crc_table, crc_zeros,
        )  # fmt: skip
        if update:
            pll = st[fk.S_PLL_FREQ_HZ]
        frame_counts[j] = nf
        off += nf
        seq = (seq + nf) % _SEQ_MOD
    for i in range(4):
        force[i] = u[i]
    return pll, carry_n, seq
