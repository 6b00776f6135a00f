"""The FPGA's firmware in software: a World device that demodulates, closes the loops and streams.

The World's averaged model already gives the pickoffs demodulated at the reference (cx, sx, cy,
sy); the firmware reads them once per block, computes the wave's elements (amplitude a,
quadrature k, angle theta, phase chi) and updates its loops, whose outputs it holds over the
next block:
  * AGC (PI on setpoint - a): a force along the wave (d q / d a), so da/dt gains F_a / 2;
  * quadrature loop (PI on k): a force along d q / d k, dk/dt gains F_q / 2;
  * PLL (PI on the phase chi, modulo pi): moves the reference frequency (world.ref_freq_hz);
  * whole-angle mode: a precession force along d q / d theta, F_p = 4 a Omega_cmd turns the wave
    at Omega_cmd; with drift compensation it adds -a D sin 4(theta - theta_tau), the force that
    cancels the damping drift dtheta/dt = (D/4) sin 4(theta - theta_tau);
  * frequency modulation: the reference gets + A sin(2 pi f_m t) (held per block).
Clearing DRIVE_EN removes every force at the next block ("cut drive").
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable

import numpy as np

from bench.analysis.slow_model import orbit_elements
from drivers.fpga import protocol as p

StreamSink = Callable[[bytes, int], None]  # (encoded frames, frame count)


def _clamp(x: float, limit: float) -> float:
    return max(-limit, min(limit, x))


class FpgaFirmware:
    """Registers and loops of the simulated FPGA; attach it to a World with `world.attach`."""

    def __init__(self, world) -> None:
        self.world = world
        self.lock = threading.RLock()
        self.regs: dict[str, float] = {r.name: int(r.default) if r.kind == "u" else r.default for r in p.REGISTERS}
        self.regs["ID"] = p.FPGA_ID
        self.regs["VERSION"] = p.PROTOCOL_VERSION
        self.regs["SAMPLE_PERIOD_S"] = world.sample_period_s
        self.regs["REF_FREQ_HZ"] = world.ref_freq_hz
        self.regs["PLL_FREQ_HZ"] = world.ref_freq_hz
        self.regs["SAMPLE_INDEX"] = world.sample_index
        self.sink: StreamSink | None = None
        self._stream_seq = 0
        self._dec_sum, self._dec_n = np.zeros(4), 0  # boxcar decimator's carry between blocks
        self._reset_loops()

    # --- registers (called by the server's command thread) ----------------------------------------
    def read(self, reg: p.Register) -> float:
        with self.lock:
            if reg.name == "STATUS":
                return self._status()
            return self.regs[reg.name]

    def write(self, reg: p.Register, value: float) -> float:
        """Apply a validated write; returns the stored value."""
        with self.lock:
            if reg.name == "CTRL_SET":
                self._set_ctrl(int(self.regs["CTRL"]) | int(value))
                return value
            if reg.name == "CTRL_CLR":
                self._set_ctrl(int(self.regs["CTRL"]) & ~int(value))
                return value
            if reg.name == "CTRL":
                self._set_ctrl(int(value))
                return value
            self.regs[reg.name] = int(value) if reg.kind == "u" else float(value)
            if reg.name == "STREAM_DECIMATION":
                self._dec_sum, self._dec_n = np.zeros(4), 0
            if reg.name == "REF_FREQ_HZ" and not int(self.regs["CTRL"]) & p.PLL_EN:
                self.regs["PLL_FREQ_HZ"] = float(value)
            return self.regs[reg.name]

    def _set_ctrl(self, new: int) -> None:
        old = int(self.regs["CTRL"])
        new &= p.CTRL_MASK
        rising = new & ~old
        if rising & p.STREAM_EN:
            self._stream_seq = 0
            self._dec_sum, self._dec_n = np.zeros(4), 0
            self.regs["FRAMES_SENT"] = 0
            self.regs["STREAM_START_INDEX"] = self.regs["SAMPLE_INDEX"]
        if rising & p.PLL_EN:
            self._pll_int_hz = float(self.regs["PLL_FREQ_HZ"])
        if rising & p.AGC_EN:
            self._agc_int = 0.0
        if rising & p.QUAD_EN:
            self._quad_int = 0.0
        if not new & p.DRIVE_EN:
            self._agc_int = self._quad_int = 0.0
        self.regs["CTRL"] = new

    def _status(self) -> int:
        ctrl = int(self.regs["CTRL"])
        st = 0
        if ctrl & p.DRIVE_EN:
            st |= p.ST_DRIVE_ON
        if ctrl & p.AGC_EN and abs(self.regs["AGC_SETPOINT"] - self._a) <= 0.01 * self.regs["AGC_SETPOINT"]:
            st |= p.ST_AGC_SETTLED
        if ctrl & p.PLL_EN and abs(self._phase_err) < 0.05:
            st |= p.ST_PLL_LOCKED
        if ctrl & p.STREAM_EN:
            st |= p.ST_STREAMING
        return st

    # --- loops ----------------------------------------------------------------------------------
    def _reset_loops(self) -> None:
        self._agc_int = 0.0
        self._quad_int = 0.0
        self._pll_int_hz = float(self.regs["PLL_FREQ_HZ"])
        self._owns_ref = False  # the world's reference follows this NCO only while active
        self._phase_err = 0.0
        self._a = 0.0
        self._elements = (0.0, 0.0, 0.0, 0.0)  # a, k, theta, chi
        self._out = np.zeros(4)  # amp, freq (Hz), quad, prec outputs
        self._u: np.ndarray | None = np.zeros(4)

    def max_block_samples(self, world) -> int | None:
        """Loops update once per block: while any loop runs, blocks last one loop period."""
        with self.lock:
            ctrl = int(self.regs["CTRL"])
            if ctrl & (p.DRIVE_EN | p.PLL_EN) or (self.regs["FM_AMPLITUDE_HZ"] and self.regs["FM_RATE_HZ"]):
                return max(1, int(round(self.regs["LOOP_PERIOD_S"] / world.sample_period_s)))
        return None

    def before_block(self, world, t_s: float, n: int, dt_s: float) -> None:
        with self.lock:
            ctrl = int(self.regs["CTRL"])
            fm = 0.0
            if self.regs["FM_AMPLITUDE_HZ"] and self.regs["FM_RATE_HZ"]:
                t_mid = t_s + 0.5 * n * dt_s
                fm = self.regs["FM_AMPLITUDE_HZ"] * math.sin(2 * math.pi * self.regs["FM_RATE_HZ"] * t_mid)
            # the FPGA's NCO is the world's reference only while it drives, tracks or modulates;
            # idle, it leaves the reference to whoever drives (the front end in a MEMS sweep)
            # (one more block after going idle, so the reference ends at the NCO's final value)
            active = bool(ctrl & (p.DRIVE_EN | p.PLL_EN) or (self.regs["FM_AMPLITUDE_HZ"] and self.regs["FM_RATE_HZ"]))
            if active or self._owns_ref:
                world.ref_freq_hz = self.regs["PLL_FREQ_HZ"] + fm
            self._owns_ref = active
            self._out[1] = self.regs["PLL_FREQ_HZ"] + fm - self.regs["REF_FREQ_HZ"]
            if ctrl & p.DRIVE_EN:
                world.set_force("fpga", self._u)
            elif self._u is not None:
                self._u = None
                self._out[0] = self._out[2] = self._out[3] = 0.0
                world.set_force("fpga", None)

    def after_block(self, world, block) -> None:
        with self.lock:
            self.regs["SAMPLE_INDEX"] = int(block.index[-1])
            ctrl = int(self.regs["CTRL"])
            if ctrl & (p.DRIVE_EN | p.PLL_EN):  # nothing to update with the drive and PLL off
                self._update_loops(block.q_meas.mean(axis=0), len(block.index) * world.sample_period_s)
            if ctrl & p.STREAM_EN:
                self._emit(block)

    def _update_loops(self, q: np.ndarray, t_block_s: float) -> None:
        el = orbit_elements(q)
        a, k, theta = float(el["a"]), float(el["k"]), float(el["theta_rad"])
        c2, s2 = math.cos(2 * theta), math.sin(2 * theta)
        chi = math.atan2(-(q[1] * c2 + q[3] * s2), q[0] * c2 + q[2] * s2)
        self._a = a
        self._phase_err = (chi + 0.5 * math.pi) % math.pi - 0.5 * math.pi
        regs = self.regs
        ctrl = int(regs["CTRL"])
        if ctrl & p.PLL_EN and a > 0.01 * max(regs["AGC_SETPOINT"], 1e-12):
            self._pll_int_hz += regs["PLL_KI"] * self._phase_err * t_block_s
            regs["PLL_FREQ_HZ"] = self._pll_int_hz + regs["PLL_KP"] * self._phase_err
        if not ctrl & p.DRIVE_EN:
            return
        limit = regs["FORCE_LIMIT"]
        weak = a < 0.01 * max(regs["AGC_SETPOINT"], 1e-12)
        if weak:  # no wave to lock onto yet: excite along the x pickoff axis, in phase
            theta, chi, k = 0.0, 0.0, 0.0
            c2, s2 = 1.0, 0.0
        cc, sc = math.cos(chi), math.sin(chi)
        e_a = np.array([c2 * cc, -c2 * sc, s2 * cc, -s2 * sc])
        e_k = np.array([-s2 * sc, -s2 * cc, c2 * sc, c2 * cc])
        e_p = np.array([-s2 * cc, s2 * sc, c2 * cc, -c2 * sc])
        if ctrl & p.AGC_EN:
            err = regs["AGC_SETPOINT"] - a
            f_a = regs["AGC_KP"] * err + self._agc_int
            if abs(f_a) < limit or f_a * err < 0:  # anti-windup: integrate only off the stop
                self._agc_int += regs["AGC_KI"] * err * t_block_s
            f_a = _clamp(f_a, limit)
        else:
            f_a = _clamp(regs["DRIVE_FORCE"], limit)
        f_q = 0.0
        if ctrl & p.QUAD_EN and not weak:
            f_q = -(regs["QUAD_KP"] * k + self._quad_int)
            if abs(f_q) < limit or f_q * k > 0:
                self._quad_int += regs["QUAD_KI"] * k * t_block_s
            f_q = _clamp(f_q, limit)
        f_p = 0.0
        if ctrl & p.WHOLE_ANGLE and not weak:
            f_p = 4.0 * a * math.radians(regs["PRECESSION_RATE_DPS"])
            if ctrl & p.DRIFT_COMP_EN:
                th_tau = math.radians(regs["DRIFT_THETA_TAU_DEG"])
                f_p -= a * regs["DRIFT_D_PER_S"] * math.sin(4.0 * (theta - th_tau))
            f_p = _clamp(f_p, limit)
        self._u = f_a * e_a + f_q * e_k + f_p * e_p
        self._out[0], self._out[2], self._out[3] = f_a, f_q, f_p

    # --- stream ---------------------------------------------------------------------------------
    def _emit(self, block) -> None:
        """Stream the block, decimated by a boxcar (CIC-1) filter as the real firmware does: each
        frame carries the mean of the `dec` samples ending at its index, so decimating keeps the
        information (noise falls by sqrt(dec)) instead of throwing samples away."""
        dec = int(self.regs["STREAM_DECIMATION"])
        index = block.index
        if dec > 1:
            q = block.q_meas
            n_blk = len(index)
            i0 = int(index[0])
            if int(index[-1]) - i0 == n_blk - 1:  # consecutive samples (every World block): no scan
                pos = np.arange((-i0) % dec, n_blk, dec)
            else:
                pos = np.flatnonzero(index % dec == 0)
            csum = np.cumsum(q, axis=0)
            csum += self._dec_sum
            if len(pos):
                ends = csum[pos]
                prev_sum = np.empty_like(ends)
                prev_sum[0] = 0.0
                prev_sum[1:] = ends[:-1]
                count = np.diff(pos, prepend=-1 - self._dec_n)  # samples in each frame's mean
                means = (ends - prev_sum) / count[:, None]
                self._dec_sum = csum[-1] - ends[-1]
                self._dec_n = n_blk - 1 - int(pos[-1])
            else:
                means = np.empty((0, 4))
                self._dec_sum, self._dec_n = csum[-1], n_blk + self._dec_n
            sel = pos
        else:
            sel = slice(None)
            means = block.q_meas
        idx = index[sel]
        n = len(idx)
        if n == 0:
            return
        ch = np.empty((n, 8))
        ch[:, :4] = means
        ch[:, 4:] = self._out
        data = p.encode_stream(self._stream_seq, idx, block.t_s[sel], ch)
        self._stream_seq = (self._stream_seq + n) % p.SEQ_MOD
        self.regs["FRAMES_SENT"] += n
        if self.sink is not None:
            self.sink(data, n)
