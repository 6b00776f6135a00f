"""What the rate-sensor (CVG) procedures share: the FPGA's output mode, the stream at the rate
asked for, windows of the output recorded by their start and end, a turn-on of the resonator, and
the true values of the outputs.  A parameter mixin (not a Procedure, so it is never listed) on
top of `HrgExcitation` (excite, hold the amplitude)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from bench.analysis.cvg_rate import earth_rate_projection_dph, window_distortion, window_output
from bench.engine import Param, recorded_text

from .hrg_excitation import SETTLE_FRACTION, HrgExcitation, loops_time_constant_s, pi_loop_time_constant_s

MODES = ("whole-angle", "force-to-rebalance")


#: the truth key of the bias's turn-on to turn-on spread (1 sigma, deg/h); absent: the World has none
TURN_ON_SIGMA_KEY = "turn_on_bias_sd_dph"  # simulators/physics/noise.py


def _ftr(truth: dict[str, float]) -> bool:
    return truth.get("cvg_output_mode", 0.0) == 1.0


def nominal_scale_factor(mode: str, bryan_factor: float, ftr_gain: float, given: float = 0.0) -> float:
    """The scale factor that refers the output to the input: the one given (non-zero), else the
    mode's nominal one, G K in force-to-rebalance (the FPGA's gain G, the nominal Bryan factor K;
    1 only where a lab trimmed G to 1/K: a nominal 1 with sim-hrg-ftr's G K = 0.9972 left every
    bias 0.28 % low, issue 31 item 8), -K in whole-angle."""
    if given:
        return float(given)
    return ftr_gain * bryan_factor if mode == "force-to-rebalance" else -bryan_factor


#: the temperature the thermal procedures refer their fits to (simulators.physics.errors' reference)
REFERENCE_TEMPERATURE_C = 25.0


def _pickoff_gains(truth: dict[str, float], at_reference: bool) -> tuple[float, float]:
    """The X and Y pickoff chains' gains as the FPGA reads them: the noise model's electrode gains
    (at the start), the error sources' chain gains (`pickoff_gain_x`, `_y`: at the truth's time,
    temperature and package stress) and the FPGA's gain trims while on.  at_reference: the chains'
    gains at 25 degC off the hysteresis loop (h = 0: the middle of the heating and cooling branches),
    their temperature coefficient and the h sf_hyst / 2 taken back out (ErrorSources.pickoff_gains)."""
    shift = 0.0
    if at_reference:
        dt_k = truth.get("temperature_c", REFERENCE_TEMPERATURE_C) - REFERENCE_TEMPERATURE_C
        shift = 1e-6 * (truth.get("err_pickoff_gain_tc_ppm_k", 0.0) * dt_k
                        - 0.5 * truth.get("err_sf_hyst_ppm", 0.0) * truth.get("hysteresis_state", 0.0))
    gains = []
    for ax in ("x", "y"):
        noise = 1.0 + 1e-6 * truth.get(f"noise_gain_{ax}_ppm", 0.0)
        chain = truth.get(f"pickoff_gain_{ax}", 1.0) - shift
        gains.append((noise, chain * truth.get(f"trim_gain_{ax}", 1.0)))
    return gains[0], gains[1]


def _amplitude_ratio(truth: dict[str, float], c: float, s: float, at_reference: bool) -> float:
    """a / a_set: the wave's true amplitude over the AGC's setpoint, the setpoint being the
    pickoffs' reading of the amplitude, |(X, Y)| with X = g_x a c (1 + (3/4) e3 (n_x a c)^2) and Y
    likewise (n the noise model's electrode gain, g all the chain's gain, e3 the chains' cubic
    acting on what the electrodes give: ErrorSources.measure), solved for a by fixed point."""
    (nx, gx), (ny, gy) = _pickoff_gains(truth, at_reference)
    e3 = truth.get("err_pickoff_cubic", 0.0)
    setpoint = truth.get("agc_setpoint", 1.0)  # the register's default where a truth predates the key

    def reading(a: float) -> float:
        return math.hypot(nx * gx * a * c * (1.0 + 0.75 * e3 * (nx * a * c) ** 2),
                          ny * gy * a * s * (1.0 + 0.75 * e3 * (ny * a * s) ** 2))

    a = setpoint
    for _ in range(30):
        a = setpoint * a / reading(a)
    return a / setpoint


def scale_factor_truth(truth: dict[str, float], at_reference: bool = False) -> float:
    """The output mode's true scale factor, -K in whole-angle (the wave angle turns at -K Omega;
    unequal gains distort the angle within a turn only).  In force-to-rebalance (docs/fpga_link.md,
    "Output modes"; docs/chamber.md, "The scale factor's truth") the rate output is
    G degrees(F_p / (4 a_set)) and the rebalance force that holds the wave at theta against the
    input rate is F_c = 4 a K Omega on the node, so
        SF = G K (a / a_set) cos(phi) / g_f / (1 + trim)
    * a / a_set: the AGC holds the pickoffs' reading of the amplitude at a_set, so the true amplitude
      is a_set over the chains' gain along the wave and their cubic's (3/4) e3 a^2 (`_amplitude_ratio`:
      on the realistic HRG 1 / 1.00025 and 1 / 1.00075 at 25 degC, -250 and -749 ppm);
    * cos(phi): the readout's phase delay phi (less its trim; x's on the wave at 0, weighted by
      cos^2 2 theta and sin^2 2 theta as drive_frequency does) turns the frame the FPGA lays its
      forces in by phi off the wave's; the quadrature loop supplies the lean's other part, and F_p
      is F_c cos phi plus a quadrature force's sin phi (a bias): -609 ppm at 2 deg;
    * g_f: the forcers' gain along the node, g_fx sin^2 2 theta + g_fy cos^2 2 theta (+400 ppm for
      g_fy - 1 = -400 ppm at theta = 0);
    * trim: the thermal scale factor trim while on, TRIM_SF_PPM + TRIM_SF_PPM_PER_HZ x the PLL's
      offset from REF_FREQ_HZ (the held wave's frequency: f0 at the temperature, or at 25 degC).
    The electrodes' angle errors move it by their squares (under 2 ppm on the realistic HRG); a
    phase delay with a frequency split left a term odd in phi (-1e-5 to -2.3e-5 at 2 deg, 5 mHz)
    while the FPGA's split observer learnt in force-to-rebalance; it no longer does (docs/chamber.md,
    docs/fpga_link.md).  at_reference: at 25 degC
    mid-hysteresis (the thermal fits' value at 25 degC); else at the truth's own time,
    temperature and package stress."""
    k = truth["bryan_factor"]
    if not _ftr(truth):
        return -k
    two_th = 2.0 * math.radians(truth["ftr_angle_deg"])
    c, s = math.cos(two_th), math.sin(two_th)
    w_x = c * c
    phi_deg = (w_x * (truth.get("err_pickoff_phase_x_deg", 0.0) - truth.get("trim_phase_x_deg", 0.0))
               + (1.0 - w_x) * (truth.get("err_pickoff_phase_y_deg", 0.0) - truth.get("trim_phase_y_deg", 0.0)))
    g_f = ((1.0 - w_x) * (1.0 + 1e-6 * truth.get("err_forcer_gain_x_ppm", 0.0))
           + w_x * (1.0 + 1e-6 * truth.get("err_forcer_gain_y_ppm", 0.0)))
    sf = truth["ftr_gain"] * k * _amplitude_ratio(truth, c, s, at_reference) * math.cos(math.radians(phi_deg)) / g_f
    if "trim_sf_ppm" in truth:
        if at_reference or "f0_at_temperature_hz" not in truth:
            f_hz = truth["f0_hz"] + truth.get("freq_offset_hz_ref", truth.get("freq_offset_hz", 0.0))
        else:
            f_hz = truth["f0_at_temperature_hz"]
        f_hz += truth.get("drive_freq_offset_hz", 0.0)
        sf /= 1.0 + 1e-6 * (truth["trim_sf_ppm"] + truth.get("trim_sf_ppm_per_hz", 0.0) * (f_hz - truth["ref_freq_hz"])
                            + 0.5 * truth.get("trim_sf_hyst_ppm", 0.0) * truth.get("hyst_state", 0.0))
    return sf


def scale_factor_at_25c_truth(truth: dict[str, float]) -> float:
    """The true scale factor at 25 degC off the hysteresis loop: what a fit over a heating and a
    cooling branch gives there (scale_factor_truth at the reference)."""
    return scale_factor_truth(truth, at_reference=True)


def bias_at_dph(truth: dict[str, float], theta_deg: float) -> float:
    """The true input-referred bias with the wave at theta: the zero-rate term minus the damping
    drift referred to the input, (D / 4K) sin 4 (theta - theta_tau), in deg/h."""
    import math

    k = truth["bryan_factor"]
    drift = truth["delta_inv_tau_per_s"] / (4.0 * k) * math.sin(4.0 * math.radians(theta_deg - truth["theta_tau_deg"]))
    return 3600.0 * (truth["zero_rate_dps"] - math.degrees(drift))


#: the error sources (simulators.physics.errors, docs/error_sources.md) that add a bias the truth
#: rules below do not state: a readout's phase delay, an electrode's angle, a pickoff's
#: nonlinearity, the X/Y gain differences of the pickoffs and forcers
UNSTATED_BIAS_SOURCES = ("pickoff_phase_x_deg", "pickoff_phase_y_deg", "pickoff_angle_x_deg", "pickoff_angle_y_deg",
                         "pickoff_cubic", "pickoff_gain_diff_ppm", "forcer_gain_x_ppm", "forcer_gain_y_ppm",
                         "forcer_angle_x_deg", "forcer_angle_y_deg")

#: why a bias is compared with no truth on such a unit (said where the truth would be)
UNSTATED_BIAS_NO_TRUTH = ("no truth on a unit with readout phase delay, electrode angles, pickoff nonlinearity or "
                          "X/Y gain errors (the realistic presets): the bias they add has no closed form in the "
                          "simulator's truth (docs/error_sources.md)")


def unstated_bias_sources(truth: dict[str, float]) -> list[str]:
    """The error sources present in a unit's truth whose bias the truth rules leave out."""
    return [k for k in UNSTATED_BIAS_SOURCES if truth.get(f"err_{k}", 0.0)]


def static_bias_truth(truth: dict[str, float], turn_on_bias_dph: float | None = None) -> float | None:
    """The bias of a static record after a turn-on: at the held angle in force-to-rebalance; in
    whole-angle at 0, where a turn-on starts the wave (on the x pickoff axis); plus the turn-on's
    bias (default: the mean of the turn-on bias the World draws, its spread the repeatability's
    truth); None on a unit with error sources whose bias it leaves out."""
    if unstated_bias_sources(truth):
        return None
    turn_on = truth.get("turn_on_bias_mean_dph", 0.0) if turn_on_bias_dph is None else turn_on_bias_dph
    return bias_at_dph(truth, truth["ftr_angle_deg"] if _ftr(truth) else 0.0) + turn_on


def run_turn_on_bias_dph(truth: dict[str, float]) -> float:
    """The turn-on bias of a run that switches the drive on once (or finds it on and keeps it), from
    the truth at its start: the draw in force with the drive on, else the next turn-on's draw (the
    World draws one per drive-on); the draws' mean in a truth that names neither."""
    key = "turn_on_bias_dph" if truth.get("drive_on", 0.0) else "turn_on_bias_next_dph"
    return truth.get(key, truth.get("turn_on_bias_mean_dph", 0.0))


def mean_bias_truth(truth: dict[str, float]) -> float | None:
    """The bias a scale-factor series measures (one turn-on: `run_turn_on_bias_dph`): at the held
    angle in force-to-rebalance, the mean over the angle in whole-angle (where the drift that turns
    with the wave is fitted apart); None on a unit with error sources whose bias it leaves out."""
    if unstated_bias_sources(truth):
        return None
    if _ftr(truth):
        return static_bias_truth(truth, run_turn_on_bias_dph(truth))
    return 3600.0 * truth["zero_rate_dps"] + run_turn_on_bias_dph(truth)


def turn_on_sigma_truth(truth: dict[str, float]) -> float:
    """The true turn-on to turn-on spread of the bias (0 when the World has no such process)."""
    return truth.get(TURN_ON_SIGMA_KEY, 0.0)


class CvgOutput(HrgExcitation):
    """Params and helpers of the rate-sensor procedures; the procedure declares its window stream
    (`WINDOWS`, with at least t_start_s and t_end_s) and calls these from its steps."""

    stream_hz = Param(100.0, unit="Hz", low=0.01, high=1e6, doc="FPGA stream rate during the run (boxcar-decimated)")
    earth_rate_dph = Param(0.0, unit="deg/h", low=-20.0, high=20.0,
                           doc="Earth's rate on the sensitive axis, removed from the bias; 0 = from the station "
                               "file's latitude_deg and axis (earth_rate_projection_dph), 0 when it gives none")
    settle_s = Param(0.0, unit="s", low=0.0, high=3600.0,
                     doc="wait after the rate is stable, before averaging; 0: from the loops' bandwidth (4.6 time "
                         "constants of the slowest FPGA loop, the rebalance loop's too in force-to-rebalance)")

    _mode: str = "whole-angle"
    pause_in_record = "restart"  # a window's mean is of one continuous stretch

    def earth_rate_on_axis_dph(self, data) -> float:
        """Earth's rate to remove: the parameter when set, else the projection on the sensitive
        axis from the recorded station's latitude_deg, axis_elevation_deg, axis_azimuth_deg (its
        file's [station] keys; a run's raw file keeps them, so `analyze` gives the same)."""
        if self.earth_rate_dph:
            return float(self.earth_rate_dph)
        station = data.attrs.get("station") if hasattr(data, "attrs") else None
        st = station.get("keys", {}) if isinstance(station, dict) else {}
        if "latitude_deg" not in st:
            return 0.0
        return earth_rate_projection_dph(st["latitude_deg"], azimuth_deg=st.get("axis_azimuth_deg", 0.0),
                                         elevation_deg=st.get("axis_elevation_deg", 90.0))
    _ki_restore: bool = False

    def _scale_factor(self, ctx) -> float:
        """The procedure's `scale_factor` parameter, else the mode's nominal one (`nominal_scale_factor`,
        the FPGA's FTR_GAIN read back); the procedure declares scale_factor and bryan_factor."""
        gain = float(ctx.devices.fpga.read_register("FTR_GAIN")) if self._mode == "force-to-rebalance" else 0.0
        sf = nominal_scale_factor(self._mode, float(self.bryan_factor), gain, float(self.scale_factor))
        if sf == 0.0:
            raise RuntimeError(f"{self._mode}: scale factor 0 (FTR_GAIN {gain:g}, bryan_factor {self.bryan_factor:g})")
        return sf

    def _start_output(self, ctx) -> str:
        """Read the FPGA's output mode (the station's `output_mode`) and stream at stream_hz for the
        rest of the run (the station's decimation is restored at its end)."""
        fpga = ctx.devices.fpga
        mode = fpga.output_mode()
        if mode not in MODES:
            raise RuntimeError(f"FPGA output mode {mode!r} is not one of {MODES}")
        self._mode = mode
        dec = max(1, int(round(1.0 / (self.stream_hz * fpga.sample_period_s))))
        old = int(fpga.read_register("STREAM_DECIMATION"))
        if dec != old:
            fpga.start_stream(dec)
            ctx.defer(lambda: fpga.start_stream(old) if fpga.connected else None, "restore the stream decimation")
        ctx.log.info(f"output mode {mode}; streaming at {1.0 / (dec * fpga.sample_period_s):g} Hz")
        return mode

    def _learn_split(self, ctx, learn_deg: float, settle_s: float, rate_dps: float = 5.0) -> None:
        """Whole-angle: precess the wave learn_deg at rate_dps, then wait settle_s.  At
        rest the FPGA's split observer sees one combination of the split's 4-theta quadrature
        pattern; the other is learnt once the wave turns, and what the quadrature loop's integrator
        took up meanwhile drains over ~10 s, turned into drift by the split (+2 deg/h over a first
        window at -36 deg/s, 5 mHz: docs/fpga_link.md).  Done before the series, not in its windows."""
        if self._mode != "whole-angle" or learn_deg <= 0.0:
            return
        fpga = ctx.devices.fpga
        fpga.set_whole_angle(True, rate_dps)
        try:
            ctx.sleep(learn_deg / rate_dps)
        finally:
            fpga.set_whole_angle(True, 0.0)
        ctx.sleep(settle_s)
        ctx.log.info(f"wave precessed {learn_deg:g} deg for the FPGA to learn the split; settled {settle_s:g} s")

    def _settle_s(self, ctx) -> float:
        """settle_s, or (0) the loops' settle time from their gain registers (settle_time_s)."""
        if self.settle_s > 0:
            return self.settle_s
        fpga = ctx.devices.fpga
        tau = loops_time_constant_s(fpga)
        if self._mode == "force-to-rebalance":  # e'' + kp e' + ki e: an integrator of gain 1 around the PI
            tau = max(tau, pi_loop_time_constant_s(float(fpga.read_register("FTR_KP")),
                                                   float(fpga.read_register("FTR_KI")), 1.0))
        return tau * math.log(1.0 / SETTLE_FRACTION)

    def _record_window(self, ctx, seconds: float, label: str = "window") -> tuple[float, float]:
        """Let the bench clock run `seconds` to an absolute deadline (ctx.record_for; a pause inside
        restarts the window, pause_in_record) and log what the stream holds; (t_start, t_end)."""
        fpga = ctx.devices.fpga
        fpga.sync()
        span = ctx.record_for(seconds, label, progress=lambda _f, _m: ctx.checkpoint())  # the series' progress
        fpga.sync()
        self._refuse_saturation(span.t_start_s, span.t_end_s, label)
        t = ctx.data().table("fpga")["t_s"]
        ctx.log.info(recorded_text(label, t[span.keep(t)], span))
        return span.t_start_s, span.t_end_s

    def _turn_on(self, ctx, quench_s: float) -> None:
        """A turn-on from a quiet resonator, as a cold start: the amplitude loop alone, proportional
        only and set to zero, damps the wave (at AGC_KP / 2 per s; the PLL and the quadrature loop
        are off meanwhile, so neither chases a vanishing wave), the drive is cut, then the loops
        start again: the FPGA excites along the x pickoff axis (the wave starts at angle 0) and the
        amplitude is held at the setpoint."""
        fpga = ctx.devices.fpga
        ki = float(fpga.read_register("AGC_KI"))
        if not self._ki_restore:  # whatever ends the run, the amplitude loop gets its integral gain back
            self._ki_restore = True
            ctx.defer(lambda: fpga.write_register("AGC_KI", ki) if fpga.connected else None, "restore AGC_KI")
        fpga.set_pll(False)
        fpga.set_quadrature_loop(False)
        fpga.set_agc(False)
        fpga.write_register("AGC_KI", 0.0)
        try:
            fpga.set_agc(True, 0.0)  # rising AGC_EN clears the integrator: a force -AGC_KP a
            ctx.sleep(quench_s)
            fpga.set_drive_enabled(False)
        finally:
            fpga.write_register("AGC_KI", ki)
        ctx.sleep(0.5)
        self._start_loops(ctx)
        self._hold_amplitude(ctx)


def window_outputs(data: Any, windows: dict[str, np.ndarray], mode: str) -> np.ndarray:
    """(m, 5): each window's output (mean rate output, or rate of the angle), the means of
    cos 4 theta and sin 4 theta over it weighted alike (`window_output`) and, whole-angle, what its
    rate reads per degree of a sin 4 theta / cos 4 theta angle distortion (`window_distortion`;
    0 with the wave held), from the `fpga` stream."""
    fpga = data.table("fpga")
    t = fpga["t_s"]
    boxes = windows.get("box_s", np.zeros(len(windows["t_start_s"])))
    out = []
    for t0, t1, box_s in zip(windows["t_start_s"], windows["t_end_s"], boxes, strict=True):
        sel = (t > t0) & (t <= t1)
        if sel.sum() < 3:
            raise RuntimeError(f"the window {t0:.2f}-{t1:.2f} s holds {int(sel.sum())} stream samples; 3 are needed")
        ang = fpga["angle_out_deg"][sel]
        row = window_output(t[sel], fpga["rate_out_dps"][sel], ang, mode, float(box_s))
        dist = window_distortion(t[sel], ang, float(box_s)) if mode == "whole-angle" else (0.0, 0.0)
        out.append((*row, *dist))
    return np.array(out)
