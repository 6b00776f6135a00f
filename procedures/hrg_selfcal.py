"""Whole-angle self-calibration of a rate-integrating HRG (CETC paper; issue 20; docs/selfcal.md):
push the standing wave forward over a drift period and back (wave angle 0 -> 90 -> 0 deg, the
paper's electrical 0 -> pi -> 0) again and again with frequency modulation on the frequency loop;
after every cycle identify the X/Y gain difference, the damping anisotropy, the stiffness
anisotropy and Q by least squares on the amplitude and frequency channels (bench.analysis.selfcal),
trim the identified gain difference out in the FPGA's pickoff gain trims (RAM only: the NVM keeps
its block), and compute the input rate from the precession channel with the identified drift
removed (the previous cycle's identification applied to the next cycle: causal, as in real time).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from bench.analysis import forcer_rotation
from bench.analysis import selfcal as sc
from bench.analysis.axes import AXIS_PERIOD_DEG
from bench.engine import Measurement, Param, Procedure, Result, recorded_text, step
from bench.engine.recording import window_end
from bench.streams import Column, StreamSchema, declare

from .forcer_rotation import ROTATION, ROTATION_COLUMNS, calibrate_forcer_rotation
from .hrg_damping import _StreamTap
from .hrg_excitation import HrgExcitation, refuse_above_precession_limit
from .readout_phase import PHASE_COLUMNS, PHASES, calibrate_readout_phase, result_from_rows

TAP_COLUMNS = ("t_s", "angle_out_deg", "amp_ctrl", "freq_ctrl", "prec_ctrl", "cx", "sx", "cy", "sy")
CYCLES = "hrg_selfcal_cycles"
CYCLE_COLUMNS = declare(StreamSchema(CYCLES, "hrg-selfcal", (
    Column("t_start_s", "s", doc="start of the cycle"), Column("t_end_s", "s", doc="its end"),
    Column("gain_diff_ppm", "ppm", doc="identified X/Y pickoff gain difference g_x - g_y (trim in place + residual)"),
    Column("gain_diff_se_ppm", "ppm", doc="its standard error"),
    Column("trim_diff_ppm", "ppm", doc="gain difference trimmed out in the FPGA during the cycle"),
    Column("delta_inv_tau_per_s", "1/s", doc="damping anisotropy D = Delta(1/tau)"),
    Column("delta_inv_tau_se_per_s", "1/s", doc="its standard error"),
    Column("theta_tau_deg", "deg", doc="damping axis"), Column("theta_tau_se_deg", "deg", doc="its standard error"),
    Column("split_hz", "Hz", doc="frequency split"), Column("split_se_hz", "Hz", doc="its standard error"),
    Column("theta_w_deg", "deg", doc="stiffness axis"), Column("theta_w_se_deg", "deg", doc="its standard error"),
    Column("q_factor", "1", doc="Q = w0 / gamma"), Column("q_se", "1", doc="its standard error"),
    Column("beta_c_per_s", "1/s", doc="amplitude channel's cos 4 theta term (drift model)"),
    Column("beta_s_per_s", "1/s", doc="amplitude channel's sin 4 theta term (drift model)"),
    Column("dof", "1", doc="degrees of freedom of the amplitude fit"),
    Column("loop_gain_cm_ppm", "ppm", doc="common-mode loop gain error s_m (pickoff x forcer) from the "
           "frequency-control force (0: no such force)"),
    Column("loop_gain_cm_se_ppm", "ppm", doc="its standard error"),
    Column("loop_gain_diff_ppm", "ppm", doc="X/Y loop gain difference s_d (pickoff and forcer, over 2) from the "
           "frequency-control force"),
    Column("loop_gain_diff_se_ppm", "ppm", doc="its standard error")))).names  # fmt: skip
RATES = "hrg_selfcal_rates"
RATE_COLUMNS = declare(StreamSchema(RATES, "hrg-selfcal", (
    Column("t_s", "s", doc="time of the rate sample (midpoint)"),
    Column("theta_deg", "deg", doc="measured wave angle"),
    Column("plain_dph", "deg/h", doc="plain whole-angle rate -(thdot - command) / K"),
    Column("drift_dph", "deg/h", doc="identified drift (input-referred) removed by the self-calibration"),
    Column("selfcal_dph", "deg/h", doc="self-calibrated rate (NaN in the first, learning, cycle)")))).names  # fmt: skip

#: model floor added in quadrature to the identified parameters' intervals (docs/selfcal.md, section 4):
#: terms of second order in the gain difference and the loops' own residual, measured on noise-free runs
Q_FLOOR_REL = 3e-5  # with the frequency-control force: its loop-gain floor (LOOP_GAIN_FLOOR_PPM) is in gamma
D_FLOOR_REL = 1e-3
ANGLE_FLOOR_DEG = 0.05
SPLIT_FLOOR_REL = 1e-3
#: the frequency-control force's own reading with no gain error (+16 ppm, noise-free) and the split's
#: coupling of the forcer difference into it (+25 ppm at 600 ppm): docs/selfcal.md section 2
LOOP_GAIN_FLOOR_PPM = 30.0


def _truth(key: str, scale: float = 1.0):
    """The simulator's value of a noise term times scale; a station without that noise has none (0)."""
    return lambda truth: truth.get(key, 0.0) * scale


def _floor_truth(truth: dict[str, float]) -> float:
    """The station's noise floor at 100 s (deg/h): its white drift-rate noise and bounded angle wander
    averaged over 100 s (simulators/physics/noise.py, NoiseParams.average_sd_dph)."""
    n_dph = truth.get("arw_deg_rth", 0.0) * 60.0 / 10.0
    tau_c = truth.get("noise_angle_wander_tau_s", 1.0)
    wander_dph = math.sqrt(2.0 * (1.0 - math.exp(-100.0 / tau_c))) * truth.get("noise_angle_wander_deg", 0.0) * 36.0
    return math.hypot(n_dph, wander_dph)


def _rotation_truth(truth: dict[str, float]) -> float:
    """The forcers' common rotation against the pickoffs' (deg): (f_x + f_y) / 2 - (e_x + e_y) / 2."""
    return 0.5 * (truth.get("err_forcer_angle_x_deg", 0.0) + truth.get("err_forcer_angle_y_deg", 0.0)
                  - truth.get("err_pickoff_angle_x_deg", 0.0) - truth.get("err_pickoff_angle_y_deg", 0.0))


def _gain_truth(kind: str):
    """The true X/Y loop gain difference at clock time 0 ("start") or its drift (ppm, ppm/h): the
    pickoff chains' g_x - g_y plus the forcers' (the amplitude channel's gain term sees both,
    docs/selfcal.md section 2); 0 on a station whose chains have no gain error."""
    def rule(truth: dict[str, float]) -> float:
        if kind == "start":
            return (truth.get("noise_gain_x_ppm", 0.0) - truth.get("noise_gain_y_ppm", 0.0)
                    + 2.0 * truth.get("err_pickoff_gain_diff_ppm", 0.0)
                    + truth.get("err_forcer_gain_x_ppm", 0.0) - truth.get("err_forcer_gain_y_ppm", 0.0))
        return (truth.get("noise_gain_x_drift_ppm_h", 0.0) - truth.get("noise_gain_y_drift_ppm_h", 0.0)
                + 2.0 * truth.get("err_pickoff_gain_diff_drift_ppm_h", 0.0))
    return rule


#: why a summary of the record carries no interval
_RECORD_STAT = "a statistic of this record, not an estimate of a parameter: no interval"


#: bins a cycle's amplitude fit needs: its 5 coefficients (bench.analysis.selfcal.fit_cycle), 4 more with the
#: 8 theta terms, and one to spare
AMPLITUDE_FIT_POINTS = 6
AMPLITUDE_FIT_POINTS_8THETA = 10


class HrgSelfcal(HrgExcitation, Procedure):
    """Whole-angle self-calibration: forced precession cycles with FM, gains, damping and stiffness
    anisotropy and Q identified cycle after cycle, the rate compensated."""

    name = "hrg-selfcal"
    requires = ("fpga",)
    kinds = ("hrg",)

    cycles = Param(4, unit="", low=2, high=1000, doc="forced-precession cycles (the first one only learns)")
    precession_dps = Param(0.05, unit="deg/s", low=1e-3, high=2.0,
                           doc="wave-angle precession command: a cycle (90 deg forward, back) lasts 180 / rate s")
    fm_amplitude_hz = Param(0.0, unit="Hz", low=0.0, high=1.0,
                            doc="frequency modulation of the reference (no force: identifies nothing; "
                                "0 with fm_force_hz)")
    fm_force_hz = Param(0.01, unit="Hz", low=0.0, high=1.0,
                        doc="frequency-control force (the paper's FM): a square wave moving the wave's frequency "
                            "+-this much on an ideal chain; its response gives the loop gains (0: off)")
    fm_rate_hz = Param(0.025, unit="Hz", low=0.0, high=10.0, doc="rate of either modulation")
    settle_s = Param(30.0, unit="s", low=0.0, high=3600.0, doc="loops settling in whole-angle mode first")
    stream_hz = Param(1.0, unit="Hz", low=0.1, high=100.0, doc="rate of the samples analysed (boxcar stream)")
    bin_s = Param(20.0, unit="s", low=1.0, high=600.0, doc="least-squares bins (the loops' outputs are correlated "
                                                             "over a few seconds)")
    smooth_s = Param(100.0, unit="s", low=1.0, high=3600.0, doc="bias-stability smoothing (the paper's 100 s)")
    bryan_factor = Param(0.0, unit="", low=0.0, high=1.0,
                         doc="K: the rate is the wave's rate / -K (0: the station's nominal K)")
    nominal_params = {"bryan_factor": "bryan_factor"}
    rotation_cal = Param(0, unit="", low=0, high=1000,
                         doc="setpoint steps at each of eight wave angles of the forcers' rotation calibration "
                             "before the cycles (docs/readout_phase.md section 5): the wave's turn under amplitude "
                             "steps gives the forcers' rotation against the pickoffs, whose constant drift "
                             "gamma delta_c / 2 the cycles cannot see and the rate then has removed; 0: off")
    rotation_cal_hold_s = Param(30.0, unit="s", low=5.0, high=600.0,
                                doc="each setpoint hold of that calibration (20 s read 1.3 % low, 30 s 0.15 % high)")
    rotation_cal_ratio = Param(2.0, unit="", low=1.05, high=4.0,
                               doc="the stepped setpoint over the amplitude (the turn is delta_c ln ratio)")
    drift_8theta = Param(1, unit="", low=0, high=1,
                         doc="1: the drift model carries the 8 theta terms of the pickoffs' capacitive nonlinearity, "
                             "identified from the amplitude channel (docs/selfcal.md section 8); 0: 4 theta only")
    trim_gains = Param(1, unit="", low=0, high=1, doc="1: trim the identified gain difference out after each cycle")
    phase_cal = Param(0, unit="", low=0, high=6,
                      doc="passes of the readout phase calibration before the cycles (docs/readout_phase.md): the "
                          "chains' phase read from the amplitude loop's response to the frequency-control force at "
                          "two wave angles and trimmed out (TRIM_PHASE_X/Y_DEG); 0: off (the chains taken as "
                          "calibrated); 3 null a 2 deg delay to 0.0002 deg")
    phase_cal_hold_s = Param(120.0, unit="s", low=20.0, high=3600.0,
                             doc="each hold of the phase calibration (at least 3 periods of the force: 120 s at "
                                 "0.025 Hz)")
    phase_cal_move_dps = Param(1.0, unit="deg/s", low=0.01, high=10.0,
                               doc="precession that turns the wave 45 deg between the phase calibration's two holds")
    confidence = Param(0.95, unit="", low=0.5, high=0.999, doc="level of the intervals")

    pause_in_record = "restart"  # a cycle's identification takes one continuous cycle
    measurements = (
        Measurement("q_factor", "", "Q = w0 / gamma, last cycle", truth="Q"),
        Measurement("delta_inv_tau_per_s", "1/s", "damping anisotropy D = Delta(1/tau), last cycle",
                    truth="delta_inv_tau_per_s"),
        Measurement("theta_tau_deg", "deg", "damping axis in [0, 90), last cycle", truth="theta_tau_deg",
                    period=AXIS_PERIOD_DEG),
        Measurement("split_hz", "Hz", "frequency split, last cycle", truth="split_hz"),
        Measurement("theta_w_deg", "deg", "stiffness axis in [0, 90), last cycle", truth="theta_w_deg",
                    period=AXIS_PERIOD_DEG),
        Measurement("gain_diff_start_ppm", "ppm", "X/Y loop gain difference g_x - g_y (pickoff and forcer) at clock "
                    "time 0, from the straight line through the cycles' identified values", truth=_gain_truth("start")),
        Measurement("gain_drift_ppm_h", "ppm/h", "drift of the X/Y gain difference (slope of that line)",
                    truth=_gain_truth("drift")),
        Measurement("gain_diff_last_ppm", "ppm", "X/Y gain difference identified in the last cycle"),
        Measurement("loop_gain_cm_ppm", "ppm", "common-mode loop gain error s_m (pickoff and forcer chains) the "
                    "frequency-control force met in the last cycle: the commanded precession runs 1 + s_m fast",
                    when=lambda p: p.fm_force_hz > 0, when_doc="a frequency-control force (fm_force_hz > 0)"),
        Measurement("loop_gain_diff_ppm", "ppm", "X/Y loop gain difference s_d (pickoff residual after the trims "
                    "plus forcer, (g_x - g_y) / 2 of each) the frequency-control force met in the last cycle",
                    when=lambda p: p.fm_force_hz > 0, when_doc="a frequency-control force (fm_force_hz > 0)"),
        Measurement("readout_phase_x_deg", "deg", "x readout chain's phase delay at the carrier (the trim the phase "
                    "calibration left in place; interval with its 0.001 deg floor)",
                    truth=lambda t: t.get("err_pickoff_phase_x_deg", 0.0),
                    when=lambda p: p.phase_cal > 0, when_doc="the readout phase calibration on (phase_cal > 0)"),
        Measurement("readout_phase_y_deg", "deg", "y readout chain's phase delay at the carrier, as x",
                    truth=lambda t: t.get("err_pickoff_phase_y_deg", 0.0),
                    when=lambda p: p.phase_cal > 0, when_doc="the readout phase calibration on (phase_cal > 0)"),
        Measurement("forcer_rotation_deg", "deg", "the forcers' rotation against the pickoffs from the wave's turn "
                    "under amplitude steps (its drift gamma delta_c / 2 is removed from the rate)",
                    truth=_rotation_truth,
                    when=lambda p: p.rotation_cal > 0,
                    when_doc="the forcers' rotation calibration on (rotation_cal > 0)"),
        Measurement("bias_stability_plain_dph", "deg/h", "plain whole-angle bias stability (smooth_s windows, "
                    "1 sigma), cycles after the first"),
        Measurement("bias_stability_selfcal_dph", "deg/h", "self-calibrated bias stability, same record; truth: the "
                    "station's noise floor over 100 s, its white drift-rate noise and bounded angle wander "
                    "(sqrt((60 N / 10)^2 + 2 (1 - e^(-100/tau_c)) (36 sigma_phi)^2))", truth=_floor_truth),
        Measurement("improvement", "", "plain / self-calibrated bias stability",
                    no_interval="a ratio of two bias stabilities read from the same record (their errors are "
                    "correlated): no interval; each has its own"),
        Measurement("mean_bias_dph", "deg/h", "mean self-calibrated bias since the start of the compensated record",
                    truth=lambda t: t.get("earth_rate_dph", 0.0) + t.get("turn_on_bias_mean_dph", 0.0)),
        Measurement("mean_bias_10h_dph", "deg/h", "mean bias since compensation started, after 10 h",
                    when=lambda p: (p.cycles - 1) * 180.0 / p.precession_dps > 10 * 3600.0,
                    when_doc="more than 10 h of compensated cycles: (cycles - 1) x 180 / precession_dps > 36000 s"),
        Measurement("angle_error_deg", "deg", "integrated angle error at the end (interval: +-1.96 sqrt(D(T)), "
                    "D the increment variance of the angle random walk plus bounded angle fitted to the record)",
                    truth=lambda t: 0.0),
        Measurement("angle_error_rms_first_deg", "deg", "rms of the integrated angle error over the first half",
                    no_interval=_RECORD_STAT),
        Measurement("angle_error_rms_second_deg", "deg", "rms of the integrated angle error over the second half "
                    "(about the first half's if it does not accumulate; sqrt(3) x for a random walk)",
                    no_interval=_RECORD_STAT),
        Measurement("angle_bounded_sd_deg", "deg", "bounded angle error's std, fitted to the record's increments",
                    truth=_truth("noise_angle_wander_deg"),
                    no_interval="the bounded variance and the walk share the increments' curve; the fit gives no "
                    "interval for one alone (the walk's upper bound is angle_arw_deg_rth's)"),
        Measurement("angle_arw_deg_rth", "deg/sqrt(h)", "angle random walk fitted to the record's increments",
                    truth=_truth("arw_deg_rth")),
        Measurement("angle_error_max_deg", "deg", "largest integrated angle error over the record",
                    no_interval=_RECORD_STAT),
        Measurement("adev_100s_dph", "deg/h", "Allan deviation of the self-calibrated rate at tau = smooth_s",
                    no_interval=_RECORD_STAT),
    )

    def __init__(self, params: dict[str, Any] | None = None) -> None:
        super().__init__(params)
        self._check_fm()
        self._tap = _StreamTap(TAP_COLUMNS)

    def _check_fm(self) -> None:
        """One kind of FM, and a frequency-control force the cycles can fit: ValueError naming the
        value and its limit before anything runs."""
        if self.phase_cal > 0 and not self.fm_force_hz > 0:
            raise ValueError(f"phase_cal={self.phase_cal:g}: the readout phase calibration reads the loops' response "
                             "to the frequency-control force: set fm_force_hz > 0 (or phase_cal=0)")
        if self.phase_cal > 0 and self.fm_rate_hz > 0:
            halves = int(self.phase_cal_hold_s * 2.0 * self.fm_rate_hz + 1e-9)
            if halves < 6:
                raise ValueError(f"phase_cal_hold_s={self.phase_cal_hold_s:g}: a hold of {halves} half periods of the "
                                 f"force at fm_rate_hz={self.fm_rate_hz:g}; the phase reading needs at least 6 "
                                 f"(phase_cal_hold_s >= {3.0 / self.fm_rate_hz:g})")
        if self.fm_force_hz > 0 and self.fm_amplitude_hz > 0:
            raise ValueError("fm_force_hz and fm_amplitude_hz share FM_RATE_HZ and the frequency channel: set one to 0")
        if self.fm_force_hz > 0 and (self.fm_rate_hz <= 0 or 0.5 / self.fm_rate_hz <= 2 * sc.FM_SETTLE_S):
            raise ValueError(f"fm_rate_hz={self.fm_rate_hz:g}: the frequency-control force's half period must exceed "
                             f"twice its {sc.FM_SETTLE_S:g} s settling (fm_rate_hz < {0.25 / sc.FM_SETTLE_S:g})")
        if self.fm_force_hz > 0 and self.fm_rate_hz > 0:
            cycle_s = 180.0 / abs(self.precession_dps)
            halves = int(cycle_s * 2.0 * self.fm_rate_hz)
            need = len(sc.FREQ_TERMS) + len(sc.FM_TERMS) + 1
            if halves < need:
                raise ValueError(
                    f"precession_dps={self.precession_dps:g}: a cycle of {cycle_s:g} s holds {halves} half periods of "
                    f"the frequency-control force at fm_rate_hz={self.fm_rate_hz:g}, and its fit needs at least {need} "
                    f"(precession_dps <= {180.0 * 2.0 * self.fm_rate_hz / need:g}, fm_rate_hz >= "
                    f"{need / (2.0 * cycle_s):g}, or fm_force_hz=0)")

        cycle_s = 180.0 / abs(self.precession_dps)
        bins = int(cycle_s / self.bin_s)
        need_bins = AMPLITUDE_FIT_POINTS_8THETA if self.drift_8theta else AMPLITUDE_FIT_POINTS
        if bins < need_bins:
            raise ValueError(f"bin_s={self.bin_s:g}: a cycle of {cycle_s:g} s holds {bins} bins, and the "
                             f"amplitude fit needs at least {need_bins} (bin_s <= "
                             f"{cycle_s / need_bins:g}, or a slower precession_dps)")

    def demands(self) -> list:
        return []

    def preflight(self, devices) -> None:
        """The cycles' precession command within the FPGA's force limit (read-only)."""
        refuse_above_precession_limit(self, devices, "precession_dps", self.precession_dps, "deg/s ")
        if self.phase_cal > 0:
            refuse_above_precession_limit(self, devices, "phase_cal_move_dps", self.phase_cal_move_dps, "deg/s ")

    @step("Excite, hold the amplitude, whole-angle mode with FM")
    def excite(self, ctx):
        fpga = ctx.devices.fpga
        ctx.subscribe(fpga, self._tap)
        ctx.subscribe(fpga, self._keep_latest)
        ctx.defer(self._tap.stop)
        self._start_loops(ctx)
        self._trim0 = {n: float(fpga.read_register(n)) for n in ("TRIM_EN", "TRIM_GAIN_X", "TRIM_GAIN_Y",
                                                                 "TRIM_PHASE_X_DEG", "TRIM_PHASE_Y_DEG")}
        self._trim_en = int(self._trim0["TRIM_EN"])  # the trims the cycles keep on beside the gains'
        self._phase = None
        ctx.defer(lambda: self._restore(fpga), "FPGA gain and phase trims and FM back")
        fpga.set_whole_angle(True, 0.0, self.fm_amplitude_hz, self.fm_rate_hz)
        fpga.write_register("FM_FORCE_HZ", self.fm_force_hz)
        a = self._hold_amplitude(ctx)
        self._f0_hz = float(fpga.read_register("PLL_FREQ_HZ"))
        ctx.sleep(self.settle_s)
        period = float(fpga.read_register("SAMPLE_PERIOD_S"))
        self._dec = max(1, int(round(1.0 / (self.stream_hz * period))))
        self._dt = self._dec * period
        fpga.start_stream(self._dec)
        ctx.log.info(f"amplitude {a:.4f} held, {self._f0_hz:.3f} Hz, FM {self.fm_amplitude_hz:g} Hz at "
                     f"{self.fm_rate_hz:g} Hz, stream {1 / self._dt:g} Hz")

    @step("Readout phase calibration (phase_cal passes; docs/readout_phase.md)")
    def phase_calibration(self, ctx):
        if not self.phase_cal:
            ctx.log.info("readout phase calibration off (phase_cal=0): the chains are taken as calibrated")
            return
        fpga = ctx.devices.fpga
        self._tap.take(-math.inf, math.inf)
        self._tap.on = True
        self._phase = calibrate_readout_phase(
            ctx, fpga, self._tap, TAP_COLUMNS, passes=int(self.phase_cal), hold_s=self.phase_cal_hold_s,
            move_dps=self.phase_cal_move_dps, amplitude=self.amplitude, fm_force_hz=self.fm_force_hz,
            fm_rate_hz=self.fm_rate_hz, fm_amplitude_hz=self.fm_amplitude_hz)
        self._tap.on = False
        from drivers.fpga.protocol import TRIM_PHASE  # the frame codec's numba on a run, not on loading

        self._trim_en |= TRIM_PHASE
        ctx.record(PHASES, PHASE_COLUMNS, self._phase.rows)

    @step("Forcers' rotation against the pickoffs: amplitude steps")
    def rotation_calibration(self, ctx):
        self._rotation_rad = 0.0
        self._rotation_rows = None
        if not self.rotation_cal:
            ctx.log.info("forcers' rotation calibration off (rotation_cal=0): their constant drift stays in the rate")
            return
        fpga = ctx.devices.fpga
        self._tap.take(-math.inf, math.inf)
        self._tap.on = True
        rot, se, rows = calibrate_forcer_rotation(
            ctx, fpga, self._tap, TAP_COLUMNS, steps=int(self.rotation_cal), hold_s=self.rotation_cal_hold_s,
            ratio=self.rotation_cal_ratio, amplitude=self.amplitude, move_dps=self.phase_cal_move_dps,
            fm_amplitude_hz=self.fm_amplitude_hz, fm_rate_hz=self.fm_rate_hz)
        self._tap.on = False
        self._rotation_rad = rot
        self._rotation_rows = rows
        ctx.record(ROTATION, ROTATION_COLUMNS, rows)
        ctx.log.info(f"forcers' rotation {math.degrees(rot):+.5f} +- {math.degrees(se):.5f} deg")

    def _restore(self, fpga) -> None:
        fpga.write_register("FM_AMPLITUDE_HZ", 0.0)
        fpga.write_register("FM_FORCE_HZ", 0.0)
        fpga.set_whole_angle(True, 0.0)
        for name, v in self._trim0.items():
            fpga.write_register(name, v)

    def _cycle(self, ctx, c: int, half_s: float) -> tuple[float, float]:
        """One cycle's precession, +90 deg then -90 deg, each half to an absolute deadline on the
        bench clock; a pause inside restarts the cycle (pause_in_record).  (t_start, t_end)."""
        fpga = ctx.devices.fpga
        n = max(1, int(math.ceil(half_s / 300.0)))
        while True:
            seen = len(ctx.pauses.spans)
            fpga.sync()
            t0 = ctx.clock.now()
            for h, sign in enumerate((1.0, -1.0)):
                # (the FM registers with it: set_whole_angle writes them too, and used to zero them here)
                fpga.set_whole_angle(True, sign * self.precession_dps, self.fm_amplitude_hz, self.fm_rate_hz)
                for k in range(1, n + 1):
                    ctx.sleep_until(t0 + (h + k / n) * half_s)
            fpga.sync()
            t1 = window_end(ctx.clock, t0 + 2.0 * half_s)  # the deadline, not the clock after it (paced)
            paused = ctx.pauses.since(seen)
            if not paused:
                self._refuse_saturation(t0, t1, f"cycle {c + 1}")
                return t0, t1
            self._tap.take(-math.inf, t1)  # drop the paused cycle's rows
            ctx.log.warning(f"cycle {c + 1}: paused inside it (t = {paused[0][0]:.3f} .. {paused[-1][1]:.3f} s): "
                            "the cycle restarts")

    @step("Forced-precession cycles: identify, trim, compensate")
    def run_cycles(self, ctx):
        from drivers.fpga.protocol import TRIM_GAIN  # the frame codec's numba on a run, not on loading

        fpga = ctx.devices.fpga
        half_s = 90.0 / self.precession_dps
        w = math.radians(self.precession_dps)
        trim_dg = 0.0
        prev: sc.CycleFit | None = None
        cyc_rows, rate_rows = [], []
        self._tap.take(-math.inf, math.inf)
        self._tap.on = True
        for c in range(self.cycles):
            t0, t1 = self._cycle(ctx, c, half_s)
            rows = self._tap.take(t0, t1)
            ctx.log.info(recorded_text(f"cycle {c + 1}", rows[:, TAP_COLUMNS.index("t_s")], asked_s=2.0 * half_s))
            cols = {name: rows[:, i] for i, name in enumerate(TAP_COLUMNS)}
            t = cols["t_s"]
            th = np.radians(cols["angle_out_deg"])
            cmd = np.sign(cols["prec_ctrl"]) * w
            thdot = np.gradient(th, t)
            # a frame's angle is the boxcar mean of its dt (centred dt/2 earlier), its loop outputs
            # the values at the frame: put the angle at the frame's time; the cycle's first and
            # last frames (the gain-trim step, the command's start) are left out of the fit
            th_fit = th + thdot * self._dt / 2.0
            e = slice(3, len(t) - 3)
            fit = sc.fit_cycle(t[e], th_fit[e], thdot[e], cols["amp_ctrl"][e], cols["freq_ctrl"][e],
                               amplitude=self.amplitude, f0_hz=self._f0_hz, bin_s=self.bin_s,
                               fm_rate_hz=self.fm_rate_hz if self.fm_amplitude_hz > 0 or self.fm_force_hz > 0 else 0.0,
                               fm_force_hz=self.fm_force_hz, level=self.confidence,
                               model_8theta=bool(self.drift_8theta))
            g = fit.gain_diff
            cyc_rows.append(self._cycle_row(t0, t1, fit, trim_dg))
            # rates of this cycle: the previous cycle's identification (gain trimmed out since);
            # the first cycle learns and is compensated by nothing
            tm, thm, plain = sc.rate_dph(th, t, cmd, self.bryan_factor)
            drift = np.zeros_like(plain) if prev is None else (
                -np.degrees(prev.drift_rad_s(thm, cmd[1:], gain_removed=bool(self.trim_gains))
                            + forcer_rotation.bias_drift_rad_s(float(prev.amp_coef[0]), self._rotation_rad))
                * 3600.0 / self.bryan_factor)
            comp = plain - drift if prev is not None else np.full_like(plain, np.nan)
            switch = np.flatnonzero(np.diff(np.sign(cols["prec_ctrl"])) != 0)  # command changed: drop +-2 samples
            bad = np.zeros(len(plain), bool)
            for i in switch:
                bad[max(0, i - 2): i + 3] = True
            # and the cycle's first and last 2: the command changed at its start too (the previous cycle's
            # last command), inside the first frame's boxcar when the cycle does not start on a frame
            bad[:2] = bad[-2:] = True
            plain[bad] = np.nan
            comp[bad] = np.nan
            rate_rows.append(np.column_stack([tm, np.degrees(thm), plain, drift, comp]))
            if self.trim_gains:
                trim_dg += g.value
                fpga.write_register("TRIM_GAIN_X", 1.0 / (1.0 + trim_dg / 2.0))
                fpga.write_register("TRIM_GAIN_Y", 1.0 / (1.0 - trim_dg / 2.0))
                fpga.write_register("TRIM_EN", self._trim_en | TRIM_GAIN)
            prev = fit
            ctx.record(CYCLES, CYCLE_COLUMNS, np.array([cyc_rows[-1]]))
            ctx.record(RATES, RATE_COLUMNS, rate_rows[-1])
            ctx.progress((c + 1) / self.cycles, f"cycle {c + 1}/{self.cycles}: D {fit.delta_inv_tau.value:.4g} 1/s, "
                                                f"gain {cyc_rows[-1][2]:.0f} ppm")
            ctx.log.info(f"cycle {c + 1}: Q {fit.q_factor.value:.5g}, D {fit.delta_inv_tau.value:.5g} 1/s at "
                         f"{fit.theta_tau_deg.value:.3f} deg, split {fit.split_hz.value * 1e3:.4f} mHz at "
                         f"{fit.theta_w_deg.value:.3f} deg, gain residual {g.value * 1e6:.1f} ppm")
        self._tap.on = False
        self._cycles = np.array(cyc_rows)
        self._rates = np.vstack(rate_rows)

    def _cycle_row(self, t0: float, t1: float, f: sc.CycleFit, trim_dg: float) -> list[float]:
        g, d, tt, sp, tw, q = f.gain_diff, f.delta_inv_tau, f.theta_tau_deg, f.split_hz, f.theta_w_deg, f.q_factor
        return [t0, t1, 1e6 * (trim_dg + g.value), 1e6 * g.se, 1e6 * trim_dg, d.value, d.se, tt.value, tt.se,
                sp.value, sp.se, tw.value, tw.se, q.value, q.se, float(f.amp_coef[1]), float(f.amp_coef[2]),
                float(f.dof), 1e6 * f.loop_gain_cm.value, 1e6 * f.loop_gain_cm.se, 1e6 * f.loop_gain_diff.value,
                1e6 * f.loop_gain_diff.se]

    @step("Bias stability, mean bias, angle error, Allan deviation")
    def results(self, ctx):
        for res in _analyse(self._cycles, self._rates, self.smooth_s, self._dt, self.confidence):
            ctx.report(res)
        if self._phase is not None:
            for res in _phase_results(self._phase.rows, self.confidence):
                ctx.report(res)
        if self._rotation_rows is not None:
            ctx.report(_rotation_result(self._rotation_rows, self.confidence))

    def analysis(self, data) -> list[Result]:
        """Re-compute the results of a recorded run from its cycle and rate streams."""
        if CYCLES not in data or RATES not in data:
            raise ValueError(f"{data.path.name} holds no self-calibration cycles")
        cyc, rates = data.table(CYCLES), data.table(RATES)
        n_cyc = len(cyc[CYCLE_COLUMNS[0]])
        # a record from before the frequency-control force has no loop-gain columns: NaN
        c = np.column_stack([cyc[n] if n in cyc else np.full(n_cyc, np.nan) for n in CYCLE_COLUMNS])
        r = np.column_stack([rates[n] for n in RATE_COLUMNS])
        dt = float(np.median(np.diff(r[:, 0]))) if len(r) > 1 else 1.0
        out = _analyse(c, r, self.smooth_s, dt, self.confidence)
        if PHASES in data:
            ph = data.table(PHASES)
            out += _phase_results(np.column_stack([ph[n] for n in PHASE_COLUMNS]), self.confidence)
        if ROTATION in data:
            ro = data.table(ROTATION)
            out.append(_rotation_result(np.column_stack([ro[n] for n in ROTATION_COLUMNS]), self.confidence))
        return out

    def figures(self, data) -> list:
        from procedures.figures.hrg_selfcal import figures

        return figures(self, data)


def _phase_results(rows: np.ndarray, level: float) -> list[Result]:
    """The readout chains' phase delays: the trims the calibration's last pass left, with the last
    residual's standard error and the floor (procedures.readout_phase.PHASE_FLOOR_DEG)."""
    cal = result_from_rows(rows)
    return [Result("readout_phase_x_deg", cal.phase_x_deg, ci95=_interval(cal.phase_x_deg, cal.se_x_deg, 0.0, level)),
            Result("readout_phase_y_deg", cal.phase_y_deg, ci95=_interval(cal.phase_y_deg, cal.se_y_deg, 0.0, level))]


def _rotation_result(rows: np.ndarray, level: float) -> Result:
    """The forcers' rotation: the mean of the readings' turns (bench.analysis.forcer_rotation)."""
    readings = [forcer_rotation.StepReading(float(r[0]), math.radians(r[1]), math.radians(r[2]), int(r[3]))
                for r in rows]
    rot, se = forcer_rotation.rotation_from_readings(readings)
    return Result("forcer_rotation_deg", math.degrees(rot), ci95=_interval(math.degrees(rot), math.degrees(se), 0.0,
                                                                           level))


def _interval(v: float, se: float, floor: float, level: float) -> tuple[float, float]:
    from scipy import stats

    z = float(stats.norm.ppf(0.5 + level / 2))
    h = z * math.hypot(se, floor)
    return (v - h, v + h)


def _analyse(cyc: np.ndarray, rates: np.ndarray, smooth_s: float, dt: float, level: float) -> list[Result]:
    """Results from the cycle table (CYCLE_COLUMNS) and the rate table (RATE_COLUMNS)."""
    from scipy import stats

    col = {n: cyc[:, i] for i, n in enumerate(CYCLE_COLUMNS)}
    last = {n: float(v[-1]) for n, v in col.items()}
    out = [
        Result("q_factor", last["q_factor"], ci95=_interval(last["q_factor"], last["q_se"],
                                                            Q_FLOOR_REL * last["q_factor"], level)),
        Result("delta_inv_tau_per_s", last["delta_inv_tau_per_s"], ci95=_interval(
            last["delta_inv_tau_per_s"], last["delta_inv_tau_se_per_s"], D_FLOOR_REL * last["delta_inv_tau_per_s"],
            level)),
        Result("theta_tau_deg", last["theta_tau_deg"], ci95=_interval(last["theta_tau_deg"], last["theta_tau_se_deg"],
                                                                      ANGLE_FLOOR_DEG, level)),
        Result("split_hz", last["split_hz"], ci95=_interval(last["split_hz"], last["split_se_hz"],
                                                            SPLIT_FLOOR_REL * last["split_hz"], level)),
        Result("theta_w_deg", last["theta_w_deg"], ci95=_interval(last["theta_w_deg"], last["theta_w_se_deg"],
                                                                  ANGLE_FLOOR_DEG, level)),
        Result("gain_diff_last_ppm", last["gain_diff_ppm"], ci95=_interval(last["gain_diff_ppm"],
                                                                           last["gain_diff_se_ppm"], 0.0, level)),
    ]
    if np.isfinite(last["loop_gain_cm_ppm"]) and last["loop_gain_cm_se_ppm"] > 0:
        floor = LOOP_GAIN_FLOOR_PPM
        out += [Result("loop_gain_cm_ppm", last["loop_gain_cm_ppm"],
                       ci95=_interval(last["loop_gain_cm_ppm"], last["loop_gain_cm_se_ppm"], floor, level)),
                Result("loop_gain_diff_ppm", last["loop_gain_diff_ppm"],
                       ci95=_interval(last["loop_gain_diff_ppm"], last["loop_gain_diff_se_ppm"], floor, level))]
    t_mid_h = 0.5 * (col["t_start_s"] + col["t_end_s"]) / 3600.0
    if len(t_mid_h) >= 3:
        g0, slope = sc.gain_trend(t_mid_h, col["gain_diff_ppm"], col["gain_diff_se_ppm"], level)
        out += [Result("gain_diff_start_ppm", g0.value, ci95=g0.ci), Result("gain_drift_ppm_h", slope.value,
                                                                            ci95=slope.ci)]
    r = {n: rates[:, i] for i, n in enumerate(RATE_COLUMNS)}
    first = int(np.argmax(np.isfinite(r["selfcal_dph"])))
    plain = r["plain_dph"][first:]
    comp = r["selfcal_dph"][first:]
    bs_plain = _nan_bias_stability(plain, dt, smooth_s)
    bs_comp = _nan_bias_stability(comp, dt, smooth_s)
    n_win = int(len(comp) * dt // smooth_s)
    out += [
        Result("bias_stability_plain_dph", bs_plain, ci95=sc.bias_stability_interval(bs_plain, n_win, level)),
        Result("bias_stability_selfcal_dph", bs_comp, ci95=sc.bias_stability_interval(bs_comp, n_win, level)),
        Result("improvement", bs_plain / bs_comp),
    ]
    filled = np.where(np.isfinite(comp), comp, np.nanmean(comp))
    mean_since = sc.mean_since_start_dph(filled)
    n = len(filled)
    angle = sc.integrated_angle_deg(filled, dt)
    # the spread of the mean since start and of the angle error: from the angle error's increment
    # variance D(L) fitted to this record (angle random walk plus a bounded angle; docs/selfcal.md s. 4)
    model = sc.fit_angle_error(angle, dt, min_lag_s=max(smooth_s / 10.0, dt))
    z = float(stats.norm.ppf(0.5 + level / 2))
    t_rec = n * dt
    sd_mean = model.mean_sd_dph(t_rec)
    out.append(Result("mean_bias_dph", float(mean_since[-1]), ci95=(float(mean_since[-1] - z * sd_mean),
                                                                    float(mean_since[-1] + z * sd_mean))))
    i10 = int(round(10 * 3600 / dt))
    if n >= i10:  # declared only for records of more than 10 h compensated (a cycle's edges are left out)
        m10, sd10 = float(mean_since[i10 - 1]), model.mean_sd_dph(i10 * dt)
        out.append(Result("mean_bias_10h_dph", m10, ci95=(m10 - z * sd10, m10 + z * sd10)))
    env = z * math.sqrt(float(model.increment_var_deg2(t_rec)))
    half = n // 2
    arw, arw_ci = model.arw_deg_rth()  # one-sided [0, upper]: exactly 0 is the fit on its bound
    out += [Result("angle_error_deg", float(angle[-1]), ci95=(float(angle[-1] - env), float(angle[-1] + env))),
            Result("angle_error_max_deg", float(np.max(np.abs(angle)))),
            Result("angle_error_rms_first_deg", float(np.sqrt(np.mean(angle[:half] ** 2)))),
            Result("angle_error_rms_second_deg", float(np.sqrt(np.mean(angle[half:] ** 2)))),
            Result("angle_bounded_sd_deg", math.sqrt(model.bounded_var_deg2)),
            Result("angle_arw_deg_rth", arw, ci95=arw_ci)]
    import allantools

    _taus, adev, _e, _n = allantools.oadev(filled, rate=1.0 / dt, data_type="freq", taus=np.array([smooth_s]))
    out.append(Result("adev_100s_dph", float(adev[0])))
    return out


def _nan_bias_stability(rate: np.ndarray, dt: float, smooth_s: float) -> float:
    m = max(1, int(round(smooth_s / dt)))
    n = len(rate) // m
    if n < 2:
        raise RuntimeError(f"the compensated record of {len(rate) * dt:.0f} s holds fewer than two "
                           f"{smooth_s:g} s windows")
    means = np.nanmean(np.asarray(rate[: n * m]).reshape(n, m), axis=1)
    return float(np.std(means, ddof=1))
