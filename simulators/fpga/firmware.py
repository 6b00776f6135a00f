"""The FPGA's firmware in software: a World device that demodulates, closes the loops and streams.

The World's averaged model already gives the pickoffs demodulated at the reference (cx, sx, cy,
sy); the firmware reads them once per block, computes the wave's elements (amplitude a,
quadrature k, angle theta, phase chi, and the rates of theta and chi) and updates its loops; just
before the next block it turns their wave-frame forces onto the electrodes at the wave's angle and
phase predicted for that block's middle, and holds them over it (kernels.py says why: a force held
along the wave of the block before moves the wave itself):
  * AGC (PI on setpoint - a): a force along the wave (d q / d a), so da/dt gains F_a / 2;
  * quadrature loop (PI on k): a force along d q / d k, dk/dt gains F_q / 2, plus the frequency
    split's quadrature pumping, learnt in the case frame by an observer, cancelled feed-forward;
  * PLL (PI on the phase chi, modulo pi): moves the reference frequency (world.ref_freq_hz);
  * whole-angle mode: a precession force along d q / d theta, F_p = 4 a Omega_cmd turns the wave
    at Omega_cmd; with drift compensation it adds -a D sin 4(theta - theta_tau), the force that
    cancels the damping drift dtheta/dt = (D/4) sin 4(theta - theta_tau);
  * frequency modulation: the reference gets + A sin(2 pi f_m t) (held per block);
  * output modes (OUTPUT_MODE): whole-angle streams the wave angle (angle_out_deg, unwrapped);
    force-to-rebalance holds the wave at FTR_ANGLE_DEG with a PI on the angle error whose force
    F_p is the rate output rate_out_dps = FTR_GAIN degrees(F_p / (4 AGC_SETPOINT)).
Clearing DRIVE_EN removes every force at the next block ("cut drive").
Trims held in NVM (0x40-0x4F, docs/fpga_link.md "Trims in NVM") are loaded at power-up and applied
whenever TRIM_EN says so; the safe state (CTRL_CLR) leaves them alone.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable

import numpy as np

from drivers.fpga import protocol as p

from ..physics.drive_frequency import drive_frequency_offset_hz
from . import kernels as k
from .nvm import Nvm, decode_block, encode_block

OBS_PRIOR_WEIGHT = 2000 * 0.05**3  # the split trim's weight in the observer: ~100 s of 50 ms blocks

StreamSink = Callable[[bytes, int], None]  # (encoded frames, frame count)


class FpgaFirmware:
    """Registers and loops of the simulated FPGA; attach it to a World with `world.attach`."""

    def __init__(self, world, nvm: Nvm | None = None) -> None:
        self.world = world
        self.nvm = nvm if nvm is not None else Nvm()
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
        self._frames = p.stream_frame_buffer(128)  # encoded frames of a block, reused
        self._fused_buf: np.ndarray | None = None  # those of the world's fused blocks
        self._reset_loops()
        self._nvm_reload()  # power-up: the trims come from NVM

    def truth(self) -> dict[str, float]:
        """The registers the outputs' truth needs beyond the resonator's (procedures.cvg_output):
        in force-to-rebalance its mode, hold angle and gain; nothing in whole-angle, whose scale
        factor (-K) and bias follow from the resonator alone (so a whole-angle station's truth is
        the resonator's); and the readout phase trims while TRIM_PHASE is on (trim_phase_x_deg,
        trim_phase_y_deg: against the chains' delays err_pickoff_phase_x_deg, _y_deg); with the wave
        held and its amplitude set, drive_freq_offset_hz: the frequency the PLL runs the held wave at
        minus f0_hz + freq_offset_hz, at 25 degC (simulators.physics.drive_frequency); and what the
        rate output's scale factor depends on beyond those (procedures.cvg_output.scale_factor_truth,
        docs/chamber.md "The scale factor's truth"): agc_setpoint (the pickoffs' cubic acts at the
        true amplitude), the pickoff gain trims trim_gain_x, trim_gain_y while TRIM_GAIN is on, and
        while TRIM_THERMAL is on the scale factor trim trim_sf_ppm, trim_sf_ppm_per_hz and
        ref_freq_hz (the firmware divides the output by 1 + its error at the PLL's offset from it)."""
        with self.lock:
            out: dict[str, float] = {}
            if int(self.regs["TRIM_EN"]) & p.TRIM_PHASE:  # the readout phase trims in place (docs/readout_phase.md)
                out["trim_phase_x_deg"] = float(self.regs["TRIM_PHASE_X_DEG"])
                out["trim_phase_y_deg"] = float(self.regs["TRIM_PHASE_Y_DEG"])
            if int(self.regs["OUTPUT_MODE"]) != p.MODE_FORCE_TO_REBALANCE:
                return out
            out |= {
                "cvg_output_mode": float(p.MODE_FORCE_TO_REBALANCE),
                "ftr_angle_deg": float(self.regs["FTR_ANGLE_DEG"]),
                "ftr_gain": float(self.regs["FTR_GAIN"]),
                "agc_setpoint": float(self.regs["AGC_SETPOINT"]),
            }
            trims = int(self.regs["TRIM_EN"])
            if trims & p.TRIM_GAIN:
                out["trim_gain_x"] = float(self.regs["TRIM_GAIN_X"])
                out["trim_gain_y"] = float(self.regs["TRIM_GAIN_Y"])
            if trims & p.TRIM_THERMAL:
                out["trim_sf_ppm"] = float(self.regs["TRIM_SF_PPM"])
                out["trim_sf_ppm_per_hz"] = float(self.regs["TRIM_SF_PPM_PER_HZ"])
                out["ref_freq_hz"] = float(self.regs["REF_FREQ_HZ"])
                # the hysteresis trim's scale-factor share, at the play's state when the truth is read
                out["trim_sf_hyst_ppm"] = float(self.regs["TRIM_SF_HYST_PPM"])
                out["hyst_state"] = float(self._st[k.S_HYST])
            params = getattr(self.world, "params", None)
            if params is not None and self.regs["AGC_SETPOINT"] > 0:
                out["drive_freq_offset_hz"] = drive_frequency_offset_hz(
                    params, getattr(self.world, "errors", None), setpoint=float(self.regs["AGC_SETPOINT"]),
                    angle_deg=out["ftr_angle_deg"], trim_phase_x_deg=out.get("trim_phase_x_deg", 0.0),
                    trim_phase_y_deg=out.get("trim_phase_y_deg", 0.0))
            return out

    # --- registers (called by the server's command thread) ----------------------------------------
    def read(self, reg: p.Register) -> float:
        with self.lock:
            if reg.name == "STATUS":
                return self._status()
            if reg.name == "NVM_STATUS":
                return self._nvm_status()
            if reg.name == "NVM_CRC":
                return self.nvm.crc
            if reg.name == "NVM_COMMITS":
                return self.nvm.commits
            if reg.name == "HYST_STATE":
                return float(self._st[k.S_HYST])
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
            if reg.name == "NVM_CMD":
                self._nvm_command(int(value))
                return value
            self.regs[reg.name] = int(value) if reg.kind == "u" else float(value)
            self._prm = None  # repacked for the loop kernel at the next block
            if reg.name == "STREAM_DECIMATION":
                self._dec_sum, self._dec_n = np.zeros(4), 0
            if reg.name == "OUTPUT_MODE":  # the rebalance loop starts afresh in its mode
                self._st[k.S_FTR_INT] = 0.0
            if reg.name == "TRIM_HYST_HZ":  # a new play starts on the next block's frequency (state 0)
                self._st[k.S_PLAY_OK] = self._st[k.S_HYST] = 0.0
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
            self._st[k.S_ANGLE_OK] = 0.0  # the angle output's unwrapping starts with the stream
        st = self._st
        if rising & p.PLL_EN:
            st[k.S_PLL_INT_HZ] = float(self.regs["PLL_FREQ_HZ"])
        if rising & p.AGC_EN:
            st[k.S_AGC_INT] = 0.0
        if rising & p.QUAD_EN:  # the split observer starts afresh (kept over a drive cut: the split stays)
            st[k.S_QUAD_INT] = 0.0
            st[k.S_M_CC : k.S_H_S + 1] = 0.0
            self._seed_split_observer()
        if not new & p.DRIVE_EN:
            st[k.S_AGC_INT] = st[k.S_QUAD_INT] = st[k.S_FTR_INT] = 0.0
        self.regs["CTRL"] = new
        self._prm = None  # the drift term's source (run registers or trims) follows DRIFT_COMP_EN

    # --- trims in NVM ---------------------------------------------------------------------------
    def _nvm_reload(self) -> None:
        """Trim registers from NVM (power-up, NVM_CMD=RELOAD); defaults, trims off, when NVM is not valid."""
        block = self.nvm.block()
        values = decode_block(block) if block is not None else {n: p.BY_NAME[n].default for n in p.TRIM_BLOCK}
        if float(values["TRIM_HYST_HZ"]) != float(self.regs["TRIM_HYST_HZ"]):
            self._st[k.S_PLAY_OK] = self._st[k.S_HYST] = 0.0  # another play: it starts afresh
        for name, value in values.items():
            self.regs[name] = int(value) if p.BY_NAME[name].kind == "u" else float(value)
        self._prm = None

    def _nvm_command(self, cmd: int) -> None:
        if cmd == p.NVM_COMMIT:
            self.nvm.commit(encode_block(self.regs))
        elif cmd == p.NVM_RELOAD:
            self._nvm_reload()
        elif cmd == p.NVM_ERASE:
            self.nvm.erase()

    def _nvm_status(self) -> int:
        nvm = self.nvm
        if nvm.data is None:
            return 0
        if not nvm.valid:
            return p.NVM_CRC_BAD
        held = encode_block(decode_block(nvm.block()))  # an older layout as it loads (defaults appended)
        return p.NVM_VALID | (p.NVM_MATCH if held == encode_block(self.regs) else 0)

    def _ctrl(self) -> int:
        """CTRL as the loops see it: the drift trim switches the compensation on when the bench's own is off."""
        ctrl = int(self.regs["CTRL"])
        if int(self.regs["TRIM_EN"]) & p.TRIM_DRIFT:
            ctrl |= p.DRIFT_COMP_EN
        return ctrl

    def _seed_split_observer(self) -> None:
        """With the split trim on, the observer starts from the trimmed split (as a prior of ~100 s
        of data that fresh data refines) instead of from zero.  Its pattern is the pumping of k/a:
        (h_c, h_s)_obs = (Dw/2) (-sin 4 theta_w, cos 4 theta_w), Dw = 2 pi split."""
        if not int(self.regs["TRIM_EN"]) & p.TRIM_SPLIT:
            return
        half_dw = math.pi * float(self.regs["TRIM_SPLIT_HZ"])
        four_th = 4.0 * math.radians(float(self.regs["TRIM_SPLIT_THETA_DEG"]))
        h_c, h_s = -half_dw * math.sin(four_th), half_dw * math.cos(four_th)
        st, w = self._st, OBS_PRIOR_WEIGHT
        st[k.S_M_CC] = st[k.S_M_SS] = w
        st[k.S_V_C], st[k.S_V_S] = w * h_c, w * h_s
        st[k.S_H_C], st[k.S_H_S] = k.solve_split(w, 0.0, w, w * h_c, w * h_s)

    def _gains(self) -> np.ndarray | None:
        """The pickoff gain trims (cx, sx, cy, sy), None when off or unity."""
        if not int(self.regs["TRIM_EN"]) & p.TRIM_GAIN:
            return None
        gx, gy = float(self.regs["TRIM_GAIN_X"]), float(self.regs["TRIM_GAIN_Y"])
        return None if gx == gy == 1.0 else np.array([gx, gx, gy, gy])

    def _phase_rotation(self) -> tuple[float, float, float, float] | None:
        """The readout phase trims as (cos p_x, sin p_x, cos p_y, sin p_y), None when off or zero:
        each chain's (c, s) is turned back by its trim, as a demodulation reference turned p later
        reads it (cancelling a chain delay p: simulators/physics/errors.py applies that delay)."""
        if not int(self.regs["TRIM_EN"]) & p.TRIM_PHASE:
            return None
        px, py = math.radians(float(self.regs["TRIM_PHASE_X_DEG"])), math.radians(float(self.regs["TRIM_PHASE_Y_DEG"]))
        if px == py == 0.0:
            return None
        return math.cos(px), math.sin(px), math.cos(py), math.sin(py)

    def _status(self) -> int:
        ctrl = int(self.regs["CTRL"])
        st = 0
        if ctrl & p.DRIVE_EN:
            st |= p.ST_DRIVE_ON
        a, phase_err = float(self._st[k.S_A]), float(self._st[k.S_PHASE_ERR])
        if ctrl & p.AGC_EN and abs(self.regs["AGC_SETPOINT"] - a) <= 0.01 * self.regs["AGC_SETPOINT"]:
            st |= p.ST_AGC_SETTLED
        if ctrl & p.PLL_EN and abs(phase_err) < 0.05:
            st |= p.ST_PLL_LOCKED
        if ctrl & p.STREAM_EN:
            st |= p.ST_STREAMING
        return st

    # --- loops ----------------------------------------------------------------------------------
    def _reset_loops(self) -> None:
        self._st = np.zeros(k.N_STATE)  # loop integrators, amplitude, phase error, force, outputs
        self._st[k.S_PLL_INT_HZ] = float(self.regs["PLL_FREQ_HZ"])
        self._prm: np.ndarray | None = None  # loop registers packed for the kernel (None: repack)
        self._hot: tuple = ()  # _hot_values(), made with _prm
        self._phase_rot: tuple[float, float, float, float] | None = None  # made with _hot
        self._owns_ref = False  # the world's reference follows this NCO only while active
        self._u_on = True  # the force is applied (False once the drive is cut, until it is on again)

    def _params(self) -> np.ndarray:
        prm = self._prm
        if prm is None:
            prm = self._prm = np.array([float(self.regs[name]) for name in k.PARAM_REGS])
            if not int(self.regs["CTRL"]) & p.DRIFT_COMP_EN and int(self.regs["TRIM_EN"]) & p.TRIM_DRIFT:
                prm[k.P_DRIFT_D_PER_S] = float(self.regs["TRIM_DRIFT_D_PER_S"])
                prm[k.P_DRIFT_THETA_TAU_DEG] = float(self.regs["TRIM_DRIFT_THETA_TAU_DEG"])
            if not int(self.regs["TRIM_EN"]) & p.TRIM_THERMAL:
                prm[k.P_TRIM_BIAS_DPH] = prm[k.P_TRIM_BIAS_DPH_PER_HZ] = 0.0
                prm[k.P_TRIM_SF_PPM] = prm[k.P_TRIM_SF_PPM_PER_HZ] = 0.0
                prm[k.P_TRIM_BIAS_HYST_DPH] = prm[k.P_TRIM_SF_HYST_PPM] = 0.0  # the play itself still tracks
            self._hot = self._hot_values()
        return prm

    def _hot_values(self) -> tuple:
        """What the blocks read that only a register write changes, worked out once per write
        (every write path clears `_prm`): (loop CTRL, gain trims or None, block limit in samples
        or None, FM on, stream decimation)."""
        regs = self.regs
        self._phase_rot = self._phase_rotation()  # beside the tuple: the fused path unpacks it
        fm_on = bool(regs["FM_AMPLITUDE_HZ"] and regs["FM_RATE_HZ"])
        limit = None
        if int(regs["CTRL"]) & (p.DRIVE_EN | p.PLL_EN) or fm_on:
            limit = max(1, int(round(regs["LOOP_PERIOD_S"] / self.world.sample_period_s)))
        return self._ctrl(), self._gains(), limit, fm_on, int(regs["STREAM_DECIMATION"])

    def _hot_now(self) -> tuple:
        """The cached per-write values (`_hot_values`), brought up to date after a write."""
        if self._prm is None:
            self._params()
        return self._hot

    def max_block_samples(self, world) -> int | None:
        """Loops update once per block: while any loop runs, blocks last one loop period."""
        with self.lock:
            return self._hot_now()[2]

    def before_block(self, world, t_s: float, n: int, dt_s: float) -> None:
        with self.lock:
            regs = self.regs
            prm = self._params()
            ctrl, _, _, fm_on, _ = self._hot
            fm = 0.0
            if fm_on:
                t_mid = t_s + 0.5 * n * dt_s
                fm = regs["FM_AMPLITUDE_HZ"] * math.sin(2 * math.pi * regs["FM_RATE_HZ"] * t_mid)
            # the FPGA's NCO is the world's reference only while it drives, tracks or modulates;
            # idle, it leaves the reference to whoever drives (the front end in a MEMS sweep)
            # (one more block after going idle, so the reference ends at the NCO's final value)
            active = bool(ctrl & (p.DRIVE_EN | p.PLL_EN) or fm_on)
            pll_hz = regs["PLL_FREQ_HZ"]
            if active or self._owns_ref:
                world.ref_freq_hz = pll_hz + fm  # held over the block (its forces need it)
            self._owns_ref = active
            st = self._st
            st[k.S_OUT + 1] = pll_hz + fm - regs["REF_FREQ_HZ"]
            if ctrl & p.DRIVE_EN:
                self._u_on = True
                k.wave_force(t_s, n, dt_s, world.ref_freq_hz, ctrl, prm, st)
                world.set_force("fpga", st[k.S_U : k.S_U + 4])  # the world keeps its own copy
            elif self._u_on:
                self._u_on = False
                st[k.S_U : k.S_U + 4] = 0.0
                st[k.S_F_A] = st[k.S_F_Q_P] = st[k.S_F_P] = 0.0  # no force until the loops update again
                st[k.S_OUT] = st[k.S_OUT + 2] = st[k.S_OUT + 3] = st[k.S_RATE_OUT] = 0.0
                world.set_force("fpga", None)

    def after_block(self, world, block) -> None:
        with self.lock:
            regs = self.regs
            last = block.first_index + block.n - 1
            regs["SAMPLE_INDEX"] = last
            prm = self._params()
            ctrl, gains, _, _, dec = self._hot
            q_meas = block.q_meas if gains is None else block.q_meas * gains
            rot = self._phase_rot
            if rot is not None:  # the readout phase trim: each chain's (c, s) turned back by its trim
                q_meas = _turn_back(q_meas, rot)
            update = bool(ctrl & (p.DRIVE_EN | p.PLL_EN))  # nothing to update with the drive and PLL off
            stream = bool(ctrl & p.STREAM_EN)
            st = self._st
            if update:
                st[k.S_PLL_FREQ_HZ] = regs["PLL_FREQ_HZ"]
            if stream and len(q_meas) > len(self._frames):
                self._frames = p.stream_frame_buffer(max(len(q_meas), 2 * len(self._frames)))
            dt = world.sample_period_s
            # the loops' update, then the block's stream frames, decimated by a boxcar (CIC-1) filter
            # as the real firmware does: each frame carries the mean of the `dec` samples ending at
            # its index, so decimating keeps the information (noise falls by sqrt(dec))
            n, self._dec_n = k.after_block(
                q_meas, update, last * dt, dt, world.ref_freq_hz, ctrl, prm, st,
                stream, block.first_index, dec, self._dec_sum, self._dec_n, self._stream_seq, self._frames,
                p.STREAM_CRC_TABLE, p.STREAM_CRC_ZEROS,
            )  # fmt: skip
            if update:
                regs["PLL_FREQ_HZ"] = float(st[k.S_PLL_FREQ_HZ])
            if n:
                self._sent(n)

    # --- stream ---------------------------------------------------------------------------------
    def _sent(self, n: int) -> None:
        """Hand the n frames encoded in `_frames` to the sink."""
        self._sent_frames(self._frames[:n], n)

    def _fused_frames(self, n: int) -> np.ndarray:
        """A frame buffer of at least n rows for the world's fused blocks (simulators.fused), reused."""
        buf = self._fused_buf
        if buf is None or len(buf) < n:
            buf = self._fused_buf = p.stream_frame_buffer(max(n, 2 * (0 if buf is None else len(buf))))
        return buf

    def _sent_frames(self, frames: np.ndarray, n: int) -> None:
        """Hand n encoded frames (rows of `frames`) to the sink; the stream's counters follow."""
        data = frames.tobytes()
        self._stream_seq = (self._stream_seq + n) % p.SEQ_MOD
        self.regs["FRAMES_SENT"] += n
        if self.sink is not None:
            self.sink(data, n)


def _turn_back(q: np.ndarray, rot: tuple[float, float, float, float]) -> np.ndarray:
    """The states (n, 4) with each chain's (c, s) turned back by its phase trim (a new array):
    c = c' cos p + s' sin p, s = -c' sin p + s' cos p, the inverse of a delay p (one compiled loop,
    kernels.turn_back: ~15 us of small numpy calls a block before)."""
    q = np.ascontiguousarray(q, dtype=float)
    out = np.empty_like(q)
    k.turn_back(q, *rot, out)
    return out
