"""thermal-ramp: the ramp method of thermal calibration (Niu et al., "Fast Thermal Calibration of
Low-Grade Inertial Sensors and Inertial Measurement Units", Sensors 2013; docs/chamber.md, "The
ramp method"): one heating and one cooling branch at a steady chamber ramp, recorded in short
segments throughout, both branches fitted together so a thermometer's lag cancels to first order.

Steps: excite and hold the amplitude; the chamber to t_low_degc, settled from the resonator
frequency's drift (as thermal-soak); then at `cycle_degc_per_min` up to t_high_degc and back (a
ramp-rate profile on the chamber's controller where it runs profiles, else set points from the PC),
each branch held `tail_s` once the air has arrived, the unit recorded in segments of `segment_s`
with the chamber's air and part (case) readings at each segment's start and end.  The analysis
takes each segment's bias and mean frequency and fits the bias against three thermometers: the
chamber air, the part thermocouple and the resonator frequency read as a temperature
(bench.analysis.thermal_ramp), with the rms residual of each; the frequency fit against the part
thermocouple gives the frequency's coefficient, and its heating-cooling gap the resonator's lag
behind the thermocouple."""

from __future__ import annotations

import math

import numpy as np

from bench.analysis.cvg_rate import static_bias
from bench.analysis.thermal_fit import ThermalFit, fit_temperature_polynomial
from bench.analysis.thermal_ramp import branch_gap, branch_hysteresis, frequency_thermometer, record_slope, trend_mean
from bench.engine import Demand, Measurement, Param, Procedure, Result, step
from bench.streams import Column, StreamSchema, declare

from .cvg_output import MODES, UNSTATED_BIAS_NO_TRUTH, scale_factor_at_25c_truth, static_bias_truth
from .thermal_soak import (
    BIAS_TRIM_COLUMNS,
    REF_TEMPERATURE_C,
    SETTLED_RECORD_COLUMNS,
    ThermalChamber,
    _f0_at_25c_truth,
    _f0_tc_truth,
    _pair,
    write_thermal_trim,
)

BRANCHES = ("heating", "cooling")

SEGMENTS = declare(StreamSchema("thermal_ramp_segments", "thermal-ramp", (
    Column("t_start_s", "s"), Column("t_end_s", "s"),
    Column("branch", "1", "i8", legend=dict(enumerate(BRANCHES))),
    Column("rate_dps", "deg/s", doc="the table's rate during the segment (rotate-and-static: +-rate_dps in turn)"),
    Column("air_c", "degC", doc="chamber air, mean of the segment's start and end readings"),
    Column("part_c", "degC", doc="the part thermocouple on the unit's case, mean of start and end"),
    Column("ref_freq_hz", "Hz", doc="the FPGA's REF_FREQ_HZ (the stream's freq_ctrl is relative to it)"),
    Column("mode", "1", "i8", legend={0: "whole-angle", 1: "force-to-rebalance"}),
    Column("scale_factor", "1"),
)))

#: the scale factor trim in force during a verification record
SF_TRIM_COLUMNS = (
    Column("trim_sf_ppm", "ppm", doc="TRIM_SF_PPM in force during the record (0: no scale factor trim)"),
    Column("trim_sf_ppm_per_hz", "ppm/Hz", doc="TRIM_SF_PPM_PER_HZ in force during the record"),
)
#: the hysteresis trim in force during a verification record, and the play's state
HYST_TRIM_COLUMNS = (
    Column("trim_hyst_hz", "Hz", doc="TRIM_HYST_HZ in force during the record (the hysteresis play's signed "
           "half-width; 0: no play)"),
    Column("trim_bias_hyst_dph", "deg/h", doc="TRIM_BIAS_HYST_DPH in force during the record"),
    Column("trim_sf_hyst_ppm", "ppm", doc="TRIM_SF_HYST_PPM in force during the record"),
    Column("hyst_state", "1", doc="the FPGA's HYST_STATE (the play's state, +1 after heating), mean of the "
           "record's start and end reads (0 without a play)"),
)

VERIFY = declare(StreamSchema("thermal_ramp_verify", "thermal-ramp", SETTLED_RECORD_COLUMNS + BIAS_TRIM_COLUMNS + (
    Column("approach", "1", "i8", legend={0: "from below (heating)", 1: "from above (cooling)"},
           doc="the side the set point was settled from (verify_both_branches: each point from both)"),
) + SF_TRIM_COLUMNS + HYST_TRIM_COLUMNS))

_BY_NAME = {c.name: c for c in SETTLED_RECORD_COLUMNS}
VERIFY_SF = declare(StreamSchema("thermal_ramp_verify_sf", "thermal-ramp", (
    *(_BY_NAME[n] for n in ("t_start_s", "t_end_s", "setpoint_c")),
    Column("rate_dps", "deg/s", doc="the table's rate during the record (+-rate_dps pairs)"),
    *(_BY_NAME[n] for n in ("air_c", "part_c", "ref_freq_hz", "mode", "scale_factor")),
) + SF_TRIM_COLUMNS + HYST_TRIM_COLUMNS))


def _pairs(p: dict[str, np.ndarray], rate_dps: np.ndarray, sf: np.ndarray) -> dict[str, np.ndarray]:
    """Rotate-and-static: consecutive +rate, -rate segments as one point each, the bias their mean
    (the rate cancels), the scale factor their difference over 2 rate (`sf` and `sf_se` added), the
    temperatures and frequency their means.  The segments' biases carry the rate as
    rate 3600 SF / sf_nominal (static_bias divides the output by the nominal scale factor)."""
    plus = np.flatnonzero(rate_dps[:-1] > 0)
    plus = plus[(rate_dps[plus + 1] == -rate_dps[plus]) & (p["branch"][plus] == p["branch"][plus + 1])]
    if len(plus) == 0:
        raise RuntimeError("no +rate, -rate segment pair in the cycle")
    i, j = plus, plus + 1
    out = {k: 0.5 * (v[i] + v[j]) for k, v in p.items()}
    for k in ("bias_se_dph", "f0_se_hz"):
        out[k] = 0.5 * np.hypot(p[k][i], p[k][j])
    scale = sf[i] / (2.0 * rate_dps[i] * 3600.0)
    out["sf"] = scale * (p["bias_dph"][i] - p["bias_dph"][j])
    out["sf_se"] = scale * np.hypot(p["bias_se_dph"][i], p["bias_se_dph"][j])
    out["branch"] = p["branch"][i]
    out["sf_nominal"] = sf[i]  # the nominal scale factor the run used (the trim's target)
    return out


def _sf_tc_truth(truth: dict[str, float]) -> float:
    """Force-to-rebalance's scale factor goes as 1 / the pickoff gain (the AGC holds the measured
    amplitude: scale_factor_truth), so its coefficient is minus the gains' common-mode one."""
    return -truth.get("err_pickoff_gain_tc_ppm_k", 0.0)


def _bias_hyst_truth(truth: dict[str, float]) -> float:
    """The unit's heating-minus-cooling bias on saturated branches (ErrorSources.bias_hyst_dps), deg/h."""
    return 3600.0 * truth.get("err_bias_hyst_dps", 0.0)


def _sf_hyst_truth(truth: dict[str, float]) -> float:
    """The unit's heating-minus-cooling scale factor on saturated branches (ErrorSources.sf_hyst_ppm)."""
    return truth.get("err_sf_hyst_ppm", 0.0)


def _verifying(proc) -> bool:
    return proc.verify_points > 0


def _verifying_sf(proc) -> bool:
    return proc.verify_points > 0 and proc.rate_dps > 0


def _verifying_both(proc) -> bool:
    return proc.verify_points > 0 and bool(proc.verify_both_branches)


def _hyst_trimming(proc) -> bool:
    return proc.hyst_halfwidth_degc > 0


def _hyst_trimming_sf(proc) -> bool:
    return proc.hyst_halfwidth_degc > 0 and proc.rate_dps > 0 and bool(proc.hyst_sf_trim)


def _rotating(proc) -> bool:
    return proc.rate_dps > 0


class ThermalRamp(ThermalChamber, Procedure):
    """Bias and resonator frequency against temperature from one heating and cooling ramp cycle."""

    name = "thermal-ramp"
    windows_schema = SEGMENTS

    cycle_degc_per_min = Param(1.0, unit="degC/min", low=0.01, high=50.0,
                               doc="the chamber's ramp during the cycle (ramp_degc_per_min: the approach to t_low)")
    segment_s = Param(60.0, unit="s", low=1.0, high=3600.0, doc="length of each recorded segment")
    rate_dps = Param(0.0, unit="deg/s", low=0.0, high=1000.0,
                     doc="the table at +rate_dps and -rate_dps in turn, one segment each, so each pair gives the "
                         "bias (their mean) and the scale factor (their difference) at its temperature; 0: at rest")
    accel_dps2 = Param(100.0, unit="deg/s^2", low=0.1, high=10000.0, doc="table acceleration")
    rate_tolerance_dps = Param(0.01, unit="deg/s", low=1e-6, high=10.0, doc="the rate counts as reached within this")
    rate_hold_s = Param(1.0, unit="s", low=0.0, high=600.0, doc="the rate held within tolerance before a segment")
    rate_timeout_s = Param(60.0, unit="s", low=1.0, high=3600.0, doc="longest wait for a rate")
    verify_points = Param(0, low=0, high=50,
                          doc="settled verification records after the cycle, at the middles of verify_points equal "
                              "parts of the range (between any calibration grid's points); 0: none")
    record_s = Param(300.0, unit="s", low=1.0, high=1e5, doc="each verification record once settled")
    compensate = Param(True, doc="before the verification, the thermal trim (bias against the resonator frequency) "
                                 "into the FPGA's registers (RAM; restored at the end), so the verification reads "
                                 "the unit's own compensated output")
    controller_ramp = Param(True, doc="each branch's ramp run by the chamber's controller (a ramp-rate profile, "
                                      "docs/chamber.md) where it runs profiles; off, or a controller without them: "
                                      "the set point written from the PC with the ramp limit")
    tail_s = Param(600.0, unit="s", low=0.0, high=1e5,
                   doc="record on at each end of the range once the air has arrived (the case catching up)")
    verify_both_branches = Param(False, doc="also settle each verification point from above (after settling "
                                            "hyst_guard_degc over it) and record it again: the settled bias on "
                                            "the two branches at one temperature (verify_hysteresis_dph)")
    hyst_halfwidth_degc = Param(0.0, unit="degC", low=0.0, high=10.0,
                                doc="the half-width of the package's hysteresis play the branch-aware trim assumes "
                                    "(TRIM_HYST_HZ = it times the frequency's df/dT): not fitted by the cycle (a "
                                    "short ramp's segments span more than the loop's corner), taken from the part "
                                    "type's characterisation (a slow cycle's loop corners); 0: no hysteresis trim")
    hyst_sf_trim = Param(False, doc="the scale factor's heating-minus-cooling gap into TRIM_SF_HYST_PPM too (with "
                                    "rate_dps > 0); off: 0 there (a short ramp's +-rate pairs leave that gap's "
                                    "interval +-15 000 ppm wide on the MEMS ring, 75 times its size: a trim of noise)")
    hyst_rate_term = Param(True, doc="the hysteresis fit carries a term in the frequency's rate (a bias that "
                                     "trails a moving frequency, opposite on the two branches); off: the gap alone, "
                                     "for a drive known not to trail (the firmware predicts the phase with its "
                                     "acceleration: docs/chamber.md), a several times narrower interval")
    hyst_guard_degc = Param(1.0, unit="degC", low=0.0, high=100.0,
                            doc="the hysteresis fit leaves out each branch's points within this of its turning "
                                "point (the loop's corner, on neither branch yet): more than the loop's width")

    measurements = (
        Measurement("f0_tc_ppm_k", "ppm/K", "resonator frequency's temperature coefficient at 25 degC against the "
                    "part thermocouple, both branches", truth=_f0_tc_truth),
        Measurement("f0_at_25c_hz", "Hz", "resonator frequency at 25 degC from the fit (the PLL's: the held wave's "
                    "at the AGC's amplitude)", truth=_f0_at_25c_truth),
        Measurement("bias_tc_dph_k", "deg/h/K",
                    "bias's temperature slope at 25 degC against the frequency thermometer"),
        Measurement("bias_at_25c_dph", "deg/h", "bias at 25 degC against the frequency thermometer",
                    truth=static_bias_truth,
                    no_truth=UNSTATED_BIAS_NO_TRUTH),
        Measurement("bias_fit_order", "", "polynomial order of the bias fit against the frequency thermometer (BIC)",
                    no_interval="an order chosen by a criterion"),
        Measurement("bias_rms_air_dph", "deg/h", "rms residual of the bias fitted against the chamber air",
                    no_interval="a residual"),
        Measurement("bias_rms_part_dph", "deg/h", "rms residual of the bias fitted against the part thermocouple",
                    no_interval="a residual"),
        Measurement("bias_rms_frequency_dph", "deg/h", "rms residual of the bias fitted against the resonator "
                    "frequency read as a temperature", no_interval="a residual"),
        Measurement("f0_rms_part_hz", "Hz", "rms residual of the frequency fitted against the part thermocouple",
                    no_interval="a residual"),
        Measurement("part_lag_degc", "degC", "the resonator's lag behind the part thermocouple, from the frequency "
                    "fit's heating-cooling gap (positive: the resonator trails)"),
        Measurement("thermal_bias_dph", "deg/h", "thermal trim TRIM_BIAS_DPH: the bias at the FPGA's REF_FREQ_HZ "
                    "from a straight line of the bias against the resonator frequency"),
        Measurement("thermal_bias_dph_per_hz", "deg/h/Hz", "thermal trim TRIM_BIAS_DPH_PER_HZ: that line's slope"),
        Measurement("verify_residual_dph", "deg/h", "rms bias left at the verification points by the thermal trim "
                    "(the FPGA's compensated output with `compensate`, else the trim applied in the analysis)",
                    no_interval="a residual", when=_verifying, when_doc="verify_points > 0"),
        Measurement("verify_residual_part_dph", "deg/h", "the same with the compensation against the part "
                    "thermocouple", no_interval="a residual", when=_verifying, when_doc="verify_points > 0"),
        Measurement("verify_residual_hyst_dph", "deg/h", "rms bias left at the verification points by the "
                    "branch-aware trim: the thermal trim and the hysteresis trim (bias_hysteresis_dph times the play's "
                    "state over 2: the FPGA's HYST_STATE where the play ran, else +1 from below, -1 from above)",
                    no_interval="a residual", when=lambda p: _verifying(p) and _hyst_trimming(p),
                    when_doc="verify_points > 0 and hyst_halfwidth_degc > 0"),
        Measurement("thermal_hyst_hz", "Hz", "thermal hysteresis trim TRIM_HYST_HZ: the play's half-width "
                    "hyst_halfwidth_degc (assumed) times the frequency's df/dT against the part thermocouple",
                    when=_hyst_trimming, when_doc="hyst_halfwidth_degc > 0"),
        Measurement("thermal_bias_hyst_dph", "deg/h", "thermal hysteresis trim TRIM_BIAS_HYST_DPH: "
                    "bias_hysteresis_dph (heating minus cooling), the play's state times half of it comes off",
                    when=_hyst_trimming, when_doc="hyst_halfwidth_degc > 0"),
        Measurement("thermal_sf_hyst_ppm", "ppm", "thermal hysteresis trim TRIM_SF_HYST_PPM: sf_hysteresis_ppm",
                    when=_hyst_trimming_sf, when_doc="hyst_halfwidth_degc > 0, rate_dps > 0 and hyst_sf_trim"),
        Measurement("verify_noise_dph", "deg/h", "rms of the verification records' own bias standard errors "
                    "(what the unit's noise allows a residual)", no_interval="a noise level", when=_verifying,
                    when_doc="verify_points > 0"),
        Measurement("verify_allowed_dph", "deg/h", "what the unit's noise and the trim fit's interval allow the "
                    "compensated residual: rms over the verification points of the record's bias standard error, "
                    "the thermal trim line's standard error at the point's frequency and, with the branch-aware "
                    "trim, the hysteresis gap's standard error times the play's state over 2, in quadrature",
                    no_interval="a noise level", when=_verifying, when_doc="verify_points > 0"),
        Measurement("sf_at_25c", "", "scale factor (output per input rate) at 25 degC against the frequency "
                    "thermometer, from the +-rate_dps pairs", truth=scale_factor_at_25c_truth, when=_rotating,
                    when_doc="rate_dps > 0"),
        Measurement("sf_tc_ppm_k", "ppm/K", "scale factor's temperature coefficient at 25 degC (straight line "
                    "against the frequency thermometer)", truth=_sf_tc_truth, when=_rotating, when_doc="rate_dps > 0"),
        Measurement("bias_hysteresis_dph", "deg/h", "thermal hysteresis: bias on heating minus bias on cooling at "
                    "the same temperature (frequency thermometer), fitted beside the PLL's trail on the moving "
                    "frequency (bench.analysis.thermal_ramp.branch_hysteresis)", truth=_bias_hyst_truth),
        Measurement("bias_per_freq_rate_dph_s_per_hz", "deg/h/(Hz/s)", "the bias the frequency's rate of change "
                    "adds (forces trailing a moving frequency's phase), fitted with the hysteresis",
                    when=lambda p: bool(p.hyst_rate_term), when_doc="hyst_rate_term"),
        Measurement("thermal_sf_ppm", "ppm", "thermal trim TRIM_SF_PPM: the scale factor's error (against the "
                    "nominal scale factor) at the FPGA's REF_FREQ_HZ, from the +-rate_dps pairs", when=_rotating,
                    when_doc="rate_dps > 0"),
        Measurement("thermal_sf_ppm_per_hz", "ppm/Hz", "thermal trim TRIM_SF_PPM_PER_HZ: that error's slope against "
                    "the PLL frequency's offset", when=_rotating, when_doc="rate_dps > 0"),
        Measurement("verify_sf_error_ppm", "ppm", "rms scale factor error left at the verification points (+-rate_dps "
                    "pairs of the FPGA's output, the scale factor trim in force with `compensate`)",
                    no_interval="a residual", when=_verifying_sf, when_doc="verify_points > 0 and rate_dps > 0"),
        Measurement("verify_sf_error_raw_ppm", "ppm", "the same without the scale factor trim (the records' pairs "
                    "with the trim in force taken back out)", no_interval="a residual", when=_verifying_sf,
                    when_doc="verify_points > 0 and rate_dps > 0"),
        Measurement("verify_sf_noise_ppm", "ppm", "rms of the verification pairs' own scale factor standard errors",
                    no_interval="a noise level", when=_verifying_sf, when_doc="verify_points > 0 and rate_dps > 0"),
        Measurement("verify_hysteresis_dph", "deg/h", "thermal hysteresis from settled records: the bias "
                    "settled from below minus settled from above at each verification point (no rate term, no lag), "
                    "their weighted mean", truth=_bias_hyst_truth, when=_verifying_both,
                    when_doc="verify_points > 0 and verify_both_branches"),
        Measurement("sf_hysteresis_ppm", "ppm", "scale factor on heating minus on cooling at the same temperature, "
                    "over the scale factor at 25 degC (the +-rate_dps pairs)", truth=_sf_hyst_truth, when=_rotating,
                    when_doc="rate_dps > 0"),
        Measurement("cycle_s", "s", "simulated time from the cycle's start to its last segment",
                    no_interval="a time the run took"),
    )

    def demands(self) -> list[Demand]:
        if self.rate_dps <= 0:
            return []
        return [Demand("table", "max_rate_dps", "rate_dps", self.rate_dps, "deg/s"),
                Demand("table", "max_accel_dps2", "accel_dps2", self.accel_dps2, "deg/s^2")]

    @step("Ramp cycle, recorded in segments", uses=("fpga",), shares=("chamber", "table"))
    def ramp(self, ctx):
        chamber = ctx.devices.chamber
        ref_hz = float(ctx.devices.fpga.read_register("REF_FREQ_HZ"))
        code = MODES.index(self._mode)
        sf = self._scale_factor(ctx)
        settle_s = self._settle_at(ctx, float(self.t_low_degc), ref_hz)
        ctx.log.info(f"settled at {self.t_low_degc:g} degC after {settle_s:.0f} s")
        table = None
        if self.rate_dps > 0:
            if self._mode != "force-to-rebalance":
                raise RuntimeError("rate_dps > 0 needs the force-to-rebalance output (a rate at each segment)")
            table = ctx.devices.table
            ctx.shared(table.enable, "table enabled")
            if not ctx.in_batch:  # a batch's table comes to rest once, when the batch ends
                ctx.defer(lambda: table.set_rate(0.0, self.accel_dps2) if table.connected else None, "table to rest")
        on_controller = bool(self.controller_ramp) and ctx.shared(chamber.supports_profiles, "controller profiles")
        if not on_controller:
            ctx.shared(lambda: chamber.set_ramp_rate(self.cycle_degc_per_min), "cycle ramp rate")
        ctx.log.info("the cycle's ramps run " + ("on the chamber's controller (a ramp-rate profile)" if on_controller
                                                 else "from the PC (set points with the ramp limit)"))
        span_c = self.t_high_degc - self.t_low_degc
        expected_s = 2 * (span_c / self.cycle_degc_per_min * 60.0 + self.tail_s)
        t_cycle = ctx.clock.now()
        for branch, target in enumerate((self.t_high_degc, self.t_low_degc)):
            if on_controller:
                profile = ctx.shared(lambda target=target: chamber.start_ramp(float(target), self.cycle_degc_per_min),
                                     f"{BRANCHES[branch]} ramp")
            else:
                ctx.shared(lambda target=target: chamber.set_setpoint(float(target)), f"{BRANCHES[branch]} set point")
            arrived, k = None, 0
            # with the table turning, a branch ends on a whole +- pair
            while arrived is None or ctx.clock.now() - arrived < self.tail_s or (table is not None and k % 2):
                rate = 0.0
                if table is not None:
                    rate = self.rate_dps if k % 2 == 0 else -self.rate_dps
                    self._table_at(ctx, table, rate)
                    ctx.sleep(self._settle_s(ctx))  # the rebalance loop's transient outside the segment
                k += 1
                s0 = self._chamber_status(ctx)
                t0, t1 = self._record_window(ctx, self.segment_s, f"{BRANCHES[branch]} segment at {rate:+g} deg/s")
                s1 = self._chamber_status(ctx)
                air, part = 0.5 * (s0.air_c + s1.air_c), 0.5 * (s0.part_c + s1.part_c)
                row = [t0, t1, branch, rate, air, part, ref_hz, code, sf]
                ctx.record(SEGMENTS, SEGMENTS.names, np.array([row]))
                if arrived is None and abs(s1.air_c - target) < 0.05:
                    arrived = t1
                ctx.progress(min(1.0, (ctx.clock.now() - t_cycle) / expected_s), f"{BRANCHES[branch]}, case "
                             f"{s1.part_c:.1f} degC")
            if on_controller:  # the End-Hold holds the target: the constant set point takes it over
                ctx.shared(lambda profile=profile, target=target: chamber.end_ramp(profile, float(target)),
                           f"{BRANCHES[branch]} ramp ended")
        if table is not None:
            self._table_at(ctx, table, 0.0)

    def _table_at(self, ctx, table, rate_dps: float) -> None:
        """The table to rate_dps and held there (once for a batch)."""
        def move() -> None:
            table.set_rate(rate_dps, self.accel_dps2)
            table.wait_at_rate(self.rate_tolerance_dps, self.rate_hold_s, self.rate_timeout_s)

        ctx.shared(move, f"table at {rate_dps:+g} deg/s")

    def verify_setpoints_c(self) -> np.ndarray:
        n = int(self.verify_points)
        return self.t_low_degc + (np.arange(n) + 0.5) * (self.t_high_degc - self.t_low_degc) / max(n, 1)

    @step("Verification at temperatures between", uses=("fpga",), shares=("chamber", "table"))
    def verify(self, ctx):
        if not self.verify_points:
            return
        chamber = ctx.devices.chamber
        fpga = ctx.devices.fpga
        ref_hz = float(fpga.read_register("REF_FREQ_HZ"))
        ctx.shared(lambda: chamber.set_ramp_rate(self.ramp_degc_per_min), "verification ramp rate")
        code, sf = MODES.index(self._mode), self._scale_factor(ctx)
        trim, sf_trim, hyst = (0.0, 0.0), (0.0, 0.0), (0.0, 0.0, 0.0)
        table = ctx.devices.table if self.rate_dps > 0 else None
        if self.compensate:
            if self.hyst_halfwidth_degc > 0:  # the hysteresis fit wants the frequency thermometer's points
                p, bias, _, f_line = self.fits(ctx.data())
                hyst = self.hyst_trim(p, bias["frequency"].order, f_line)
            else:
                p = self.points_table(ctx.data())
            line = self.trim_line(p)
            trim = (float(line.coeffs[0]), float(line.coeffs[1]))
            if "sf" in p:
                sf_line = self.sf_trim_line(p)
                sf_trim = (float(sf_line.coeffs[0]), float(sf_line.coeffs[1]))
            self._write_trim(ctx, trim, sf_trim, hyst)
        sps = list(self.verify_setpoints_c())
        visits = [(float(sp), 0) for sp in sps]  # the cycle ended at t_low: each point from below
        if self.verify_both_branches:  # then each from above, highest first, after settling over it
            visits += [(float(sp), 1) for sp in sps[::-1]]
        for sp, approach in visits:
            if approach == 1:
                self._settle_at(ctx, sp + float(self.hyst_guard_degc), ref_hz)
            settle_s = self._settle_at(ctx, sp, ref_hz)
            s0 = self._chamber_status(ctx)
            h0 = float(fpga.read_register("HYST_STATE"))
            side = ("from below", "from above")[approach]
            t0, t1 = self._record_window(ctx, self.record_s, f"verification {sp:g} degC record ({side})")
            s1 = self._chamber_status(ctx)
            h = 0.5 * (h0 + float(fpga.read_register("HYST_STATE")))
            row = [t0, t1, sp, 0.5 * (s0.air_c + s1.air_c), 0.5 * (s0.part_c + s1.part_c), settle_s, ref_hz, code, sf,
                   *trim, approach, *sf_trim, *hyst, h]
            ctx.record(VERIFY, VERIFY.names, np.array([row]))
            if table is not None and approach == 0:  # the scale factor there: a +-rate pair, from below
                for rate in (self.rate_dps, -self.rate_dps):
                    self._table_at(ctx, table, rate)
                    ctx.sleep(self._settle_s(ctx))
                    s0 = self._chamber_status(ctx)
                    h0 = float(fpga.read_register("HYST_STATE"))
                    t0, t1 = self._record_window(ctx, self.record_s, f"verification {sp:g} degC at {rate:+g} deg/s")
                    s1 = self._chamber_status(ctx)
                    h = 0.5 * (h0 + float(fpga.read_register("HYST_STATE")))
                    row = [t0, t1, sp, rate, 0.5 * (s0.air_c + s1.air_c), 0.5 * (s0.part_c + s1.part_c), ref_hz,
                           code, sf, *sf_trim, *hyst, h]
                    ctx.record(VERIFY_SF, VERIFY_SF.names, np.array([row]))
                self._table_at(ctx, table, 0.0)

    def _write_trim(self, ctx, trim: tuple[float, float], sf_trim: tuple[float, float] = (0.0, 0.0),
                    hyst: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> None:
        """The thermal trim (bias, scale factor and the hysteresis trim: TRIM_HYST_HZ, TRIM_BIAS_HYST_DPH,
        TRIM_SF_HYST_PPM) into the FPGA's registers and TRIM_EN's TRIM_THERMAL bit (RAM only: the line
        commits trims to NVM for PASS units); the registers before are restored at the end."""
        write_thermal_trim(ctx, {"TRIM_BIAS_DPH": trim[0], "TRIM_BIAS_DPH_PER_HZ": trim[1],
                                 "TRIM_SF_PPM": sf_trim[0], "TRIM_SF_PPM_PER_HZ": sf_trim[1],
                                 "TRIM_HYST_HZ": hyst[0], "TRIM_BIAS_HYST_DPH": hyst[1], "TRIM_SF_HYST_PPM": hyst[2]})
        ctx.log.info(f"thermal trim on: {trim[0]:.4g} deg/h at REF_FREQ_HZ, {trim[1]:.4g} deg/h/Hz; scale factor "
                     f"{sf_trim[0]:.4g} ppm, {sf_trim[1]:.4g} ppm/Hz; hysteresis {hyst[1]:.4g} deg/h, "
                     f"{hyst[2]:.4g} ppm over a play of {hyst[0]:.4g} Hz")

    def hyst_trim(self, p: dict[str, np.ndarray], bias_order: int, f_line: ThermalFit) -> tuple[float, float, float]:
        """The hysteresis trim (TRIM_HYST_HZ, TRIM_BIAS_HYST_DPH, TRIM_SF_HYST_PPM) from the cycle's points:
        the assumed half-width hyst_halfwidth_degc times df/dT (f_line: frequency against the part
        thermocouple, Hz/K) and the fitted heating-minus-cooling gaps (0 where the fit could not be made)."""
        if not self.hyst_halfwidth_degc > 0:
            return (0.0, 0.0, 0.0)
        fits = self._hyst_fits(p, min(max(bias_order, 1), 2))
        if fits is None:
            return (0.0, 0.0, 0.0)
        hb, sf_gap_ppm = fits
        h_hz = float(self.hyst_halfwidth_degc) * float(f_line.coeffs[1])
        return (h_hz, float(hb.gap), float(sf_gap_ppm[0]) if sf_gap_ppm is not None and self.hyst_sf_trim else 0.0)

    @step("Fits against temperature", uses=())
    def estimate(self, ctx):
        for res in self.analysis(ctx.data()):
            ctx.report(res)

    # --- analysis --------------------------------------------------------------------------
    def points_table(self, data, schema: StreamSchema = SEGMENTS) -> dict[str, np.ndarray]:
        """Each segment's branch, air and part readings, bias (deg/h) and frequency (Hz) with
        standard errors (the frequency's about its own drift within the segment); with VERIFY,
        the verification records' (branch: -1)."""
        seg = data.table(schema.name)
        fpga = data.table("fpga")
        t = fpga["t_s"]
        earth_dph = self.earth_rate_on_axis_dph(data)
        rows = []
        branches = seg["branch"] if "branch" in schema.names else np.full(len(seg["t_start_s"]), -1.0)
        cols = ("t_start_s", "t_end_s", "air_c", "part_c", "ref_freq_hz", "mode", "scale_factor")
        for br, (t0, t1, air, part, ref, mode, sf) in zip(branches, zip(*(seg[c] for c in cols), strict=True),
                                                           strict=True):
            sel = (t > t0) & (t <= t1)
            name = MODES[int(mode)]
            y = fpga["rate_out_dps"][sel] if name == "force-to-rebalance" else fpga["angle_out_deg"][sel]
            b = static_bias(t[sel], y, mode=name, scale_factor=float(sf), earth_rate_dph=earth_dph,
                            n_batches=self.batches)
            f, f_se = trend_mean(fpga["freq_ctrl"][sel], self.batches)
            f_rate = record_slope(t[sel], fpga["freq_ctrl"][sel])
            rows.append((0.5 * (t0 + t1), br, air, part, b.bias_dph, b.sigma_dph, ref + f, f_se, f, f_rate))
        a = np.array(rows, dtype=float).reshape(-1, 10)
        keys = ("t_s", "branch", "air_c", "part_c", "bias_dph", "bias_se_dph", "f0_hz", "f0_se_hz", "f_offset_hz",
                "f_rate_hz_s")
        out = {k: a[:, i] for i, k in enumerate(keys)}
        if "rate_dps" in schema.names and np.any(seg["rate_dps"] != 0):
            out = _pairs(out, np.asarray(seg["rate_dps"], dtype=float), np.asarray(seg["scale_factor"], dtype=float))
        return out

    def verification(self, data) -> dict[str, np.ndarray]:
        """The verification records' points (points_table) and raw_bias_dph: the bias the unit has
        before any trim, what the record shows plus the trim in force during it."""
        v = self.points_table(data, VERIFY)
        vt = data.table(VERIFY.name)
        n = len(v["bias_dph"])  # the firmware took the bias trim off, then divided by 1 + the scale factor trim
        zero = np.zeros(n)
        s = np.asarray(vt.get("hyst_state", zero))  # the play's state (its trims' halves times it)
        sf_ppm = (np.asarray(vt.get("trim_sf_ppm", zero)) + np.asarray(vt.get("trim_sf_ppm_per_hz", zero))
                  * v["f_offset_hz"] + 0.5 * np.asarray(vt.get("trim_sf_hyst_ppm", zero)) * s)
        v["raw_bias_dph"] = (v["bias_dph"] * (1.0 + 1e-6 * sf_ppm) + vt["trim_bias_dph"]
                             + vt["trim_bias_dph_per_hz"] * v["f_offset_hz"]
                             + 0.5 * np.asarray(vt.get("trim_bias_hyst_dph", zero)) * s)
        # the branch each record is on: the FPGA's play where it ran, else the side it was settled from
        approach = np.asarray(vt.get("approach", zero))
        ran = np.asarray(vt.get("trim_hyst_hz", zero)) != 0.0
        v["branch_state"] = np.where(ran, s, np.where(approach == 1, -1.0, 1.0))
        return v

    def trim_line(self, p: dict[str, np.ndarray]) -> ThermalFit:
        """The thermal trim: a straight line of the segments' bias against their frequency's offset
        from REF_FREQ_HZ (what the FPGA's PLL register holds), the frequencies' own errors carried."""
        seg_ref = p["f0_hz"] - p["f_offset_hz"]
        if not np.allclose(seg_ref, seg_ref[0], rtol=0.0, atol=1e-6):
            raise RuntimeError("REF_FREQ_HZ changed during the cycle: one thermal trim cannot hold it")
        return fit_temperature_polynomial(p["f_offset_hz"], p["bias_dph"], p["bias_se_dph"], max_order=1, min_order=1,
                                          t_ref_c=0.0, sigma_t_c=float(np.median(p["f0_se_hz"])))

    def sf_trim_line(self, p: dict[str, np.ndarray]) -> ThermalFit:
        """The scale factor trim: a straight line of the pairs' scale factor error against the nominal
        (ppm: 1e6 (sf / nominal - 1)) against their frequency's offset from REF_FREQ_HZ, as trim_line."""
        nominal = float(np.median(p["sf_nominal"]))  # as recorded: the mode's nominal (G K) or the one given
        err_ppm = 1e6 * (p["sf"] / nominal - 1.0)
        return fit_temperature_polynomial(p["f_offset_hz"], err_ppm, 1e6 * p["sf_se"] / abs(nominal), max_order=1,
                                          min_order=1, t_ref_c=0.0, sigma_t_c=float(np.median(p["f0_se_hz"])))

    def verification_sf(self, data) -> dict[str, np.ndarray]:
        """The verification's +-rate pairs (points_table of VERIFY_SF) with err_ppm, the scale factor error
        of the FPGA's output (the trim in force), err_raw_ppm the unit's own (the trim taken back out:
        the firmware divides the output by 1 + its error) and err_se_ppm."""
        v = self.points_table(data, VERIFY_SF)
        vt = data.table(VERIFY_SF.name)
        plus = np.flatnonzero(np.asarray(vt["rate_dps"]) > 0)
        plus = plus[plus + 1 < len(vt["rate_dps"])]
        trim_ppm = np.asarray(vt["trim_sf_ppm"])[plus] + np.asarray(vt["trim_sf_ppm_per_hz"])[plus] * v["f_offset_hz"]
        if "trim_sf_hyst_ppm" in vt:  # the hysteresis trim's half times the play's state (the pair's mean)
            s = 0.5 * (np.asarray(vt["hyst_state"])[plus] + np.asarray(vt["hyst_state"])[plus + 1])
            trim_ppm = trim_ppm + 0.5 * np.asarray(vt["trim_sf_hyst_ppm"])[plus] * s
        nominal = float(np.median(v["sf_nominal"]))
        v["err_ppm"] = 1e6 * (v["sf"] / nominal - 1.0)
        v["err_raw_ppm"] = 1e6 * (v["sf"] * (1.0 + 1e-6 * trim_ppm) / nominal - 1.0)
        v["err_se_ppm"] = 1e6 * v["sf_se"] / abs(nominal)
        return v

    def fits(self, data) -> tuple[dict[str, np.ndarray], dict[str, ThermalFit], ThermalFit, ThermalFit]:
        """The points, the bias fit against each thermometer, the frequency fit against the part
        thermocouple (BIC order) and the frequency thermometer's straight line."""
        p = self.points_table(data)
        if len(p["part_c"]) < 4:
            raise RuntimeError(f"{len(p['part_c'])} segment(s): the fits need 4 or more")
        sig_t = self.resolution_degc / math.sqrt(12.0)
        kw = dict(max_order=int(self.max_order), t_ref_c=REF_TEMPERATURE_C)
        t_f, t_f_se, line = frequency_thermometer(p["f0_hz"], p["f0_se_hz"], p["part_c"], t_ref_c=REF_TEMPERATURE_C,
                                                  sigma_t_c=sig_t)
        p["frequency_c"] = t_f
        bias = {
            "air": fit_temperature_polynomial(p["air_c"], p["bias_dph"], p["bias_se_dph"], sigma_t_c=sig_t, **kw),
            "part": fit_temperature_polynomial(p["part_c"], p["bias_dph"], p["bias_se_dph"], sigma_t_c=sig_t, **kw),
            # the frequency thermometer's error is each segment's own (its mean frequency's)
            "frequency": fit_temperature_polynomial(t_f, p["bias_dph"], p["bias_se_dph"],
                                                    sigma_t_c=float(np.median(t_f_se)), **kw),
        }
        f0 = fit_temperature_polynomial(p["part_c"], p["f0_hz"], p["f0_se_hz"], sigma_t_c=sig_t, **kw)
        return p, bias, f0, line

    def analysis(self, data) -> list[Result]:
        """The fits' results from a recorded run's `thermal_ramp_segments` and `fpga` streams."""
        p, bias, f0, line = self.fits(data)
        f25 = float(f0.coeffs[0])
        fb = bias["frequency"]
        if fb.order >= 1:
            b_slope, b_ci = float(fb.coeffs[1]), _pair(fb.ci95[1])
        else:  # the BIC kept no slope: the straight line's, with its interval (holding 0)
            lin = fit_temperature_polynomial(p["frequency_c"], p["bias_dph"], p["bias_se_dph"], max_order=1,
                                             min_order=1, t_ref_c=REF_TEMPERATURE_C)
            b_slope, b_ci = float(lin.coeffs[1]), _pair(lin.ci95[1])
        f0_s = f0 if f0.order >= 1 else line
        lo, hi = f0_s.ci95[1]
        gap = branch_gap(f0, p["branch"] == 0, f0.slope_at(float(np.mean(p["part_c"]))))
        rms = {k: float(np.sqrt(np.mean(fit.residuals**2))) for k, fit in bias.items()}
        seg = data.table(SEGMENTS.name)
        trim = self.trim_line(p)
        out = []
        if "sf" in p:
            sf_line = fit_temperature_polynomial(p["frequency_c"], p["sf"], p["sf_se"], max_order=1, min_order=1,
                                                 t_ref_c=REF_TEMPERATURE_C)
            sf25 = float(sf_line.coeffs[0])
            sf_lo, sf_hi = sf_line.ci95[1]
            out += [Result("sf_at_25c", sf25, ci95=_pair(sf_line.ci95[0])),
                    Result("sf_tc_ppm_k", float(sf_line.coeffs[1] / sf25 * 1e6),
                           ci95=(float(sf_lo / sf25 * 1e6), float(sf_hi / sf25 * 1e6)))]
            sf_trim = self.sf_trim_line(p)
            out += [Result("thermal_sf_ppm", float(sf_trim.coeffs[0]), ci95=_pair(sf_trim.ci95[0])),
                    Result("thermal_sf_ppm_per_hz", float(sf_trim.coeffs[1]), ci95=_pair(sf_trim.ci95[1]))]
        out += [Result("thermal_bias_dph", float(trim.coeffs[0]), ci95=_pair(trim.ci95[0])),
               Result("thermal_bias_dph_per_hz", float(trim.coeffs[1]), ci95=_pair(trim.ci95[1]))]
        hyst = self._hyst_fits(p, min(max(fb.order, 1), 2))
        out += self._hysteresis(hyst)
        if self.hyst_halfwidth_degc > 0 and hyst is not None:
            h_lo, h_hi = sorted(float(self.hyst_halfwidth_degc) * np.asarray(line.ci95[1], dtype=float))
            out.append(Result("thermal_hyst_hz", float(self.hyst_halfwidth_degc * line.coeffs[1]), ci95=(h_lo, h_hi)))
            out.append(Result("thermal_bias_hyst_dph", hyst[0].gap, ci95=hyst[0].gap_ci95))
            if hyst[1] is not None and self.hyst_sf_trim:
                out.append(Result("thermal_sf_hyst_ppm", float(hyst[1][0]),
                                  ci95=(float(hyst[1][1][0]), float(hyst[1][1][1]))))
        if self.verify_points:
            v = self.verification(data)
            raw = v["raw_bias_dph"]
            left = raw - trim(v["f_offset_hz"])
            if hyst is not None and self.hyst_halfwidth_degc > 0:  # the branch-aware trim's residual
                out.append(Result("verify_residual_hyst_dph",
                                  float(np.sqrt(np.mean((left - 0.5 * hyst[0].gap * v["branch_state"]) ** 2)))))
            allowed_var = v["bias_se_dph"] ** 2 + trim.se_at(v["f_offset_hz"]) ** 2
            if hyst is not None and self.hyst_halfwidth_degc > 0:
                gap_se = (hyst[0].gap_ci95[1] - hyst[0].gap_ci95[0]) / (2.0 * 1.959964)
                allowed_var = allowed_var + (0.5 * gap_se * v["branch_state"]) ** 2
            out += [
                Result("verify_allowed_dph", float(np.sqrt(np.mean(allowed_var)))),
                Result("verify_residual_dph", float(np.sqrt(np.mean(left**2)))),
                Result("verify_residual_part_dph", float(np.sqrt(np.mean((raw - bias["part"](v["part_c"])) ** 2)))),
                Result("verify_noise_dph", float(np.sqrt(np.mean(v["bias_se_dph"] ** 2)))),
            ]
            out += self._verify_hysteresis(data, v)
            if VERIFY_SF.name in data and len(data.table(VERIFY_SF.name)["t_start_s"]) >= 2:
                vs = self.verification_sf(data)
                out += [Result("verify_sf_error_ppm", float(np.sqrt(np.mean(vs["err_ppm"] ** 2)))),
                        Result("verify_sf_error_raw_ppm", float(np.sqrt(np.mean(vs["err_raw_ppm"] ** 2)))),
                        Result("verify_sf_noise_ppm", float(np.sqrt(np.mean(vs["err_se_ppm"] ** 2))))]
        return out + [
            Result("f0_tc_ppm_k", float(f0_s.coeffs[1] / f25 * 1e6),
                   ci95=(float(lo / f25 * 1e6), float(hi / f25 * 1e6))),
            Result("f0_at_25c_hz", f25, ci95=_pair(f0.ci95[0])),
            Result("bias_tc_dph_k", b_slope, ci95=b_ci),
            Result("bias_at_25c_dph", float(fb.coeffs[0]), ci95=_pair(fb.ci95[0])),
            Result("bias_fit_order", float(fb.order)),
            Result("bias_rms_air_dph", rms["air"]),
            Result("bias_rms_part_dph", rms["part"]),
            Result("bias_rms_frequency_dph", rms["frequency"]),
            Result("f0_rms_part_hz", float(np.sqrt(np.mean(f0.residuals**2)))),
            Result("part_lag_degc", gap.lag_c, ci95=gap.lag_ci95_c),
            Result("cycle_s", float(seg["t_end_s"][-1] - seg["t_start_s"][0])),
        ]

    def _verify_hysteresis(self, data, v: dict[str, np.ndarray]) -> list[Result]:
        """Settled from below minus settled from above at each verification point (the unit's own bias,
        the trim in force added back), their inverse-variance mean with a normal 95 % interval."""
        vt = data.table(VERIFY.name)
        if "approach" not in vt or not np.any(vt["approach"] == 1):
            return []
        gaps, var = [], []
        for sp in np.unique(vt["setpoint_c"]):
            up = (vt["setpoint_c"] == sp) & (vt["approach"] == 0)
            down = (vt["setpoint_c"] == sp) & (vt["approach"] == 1)
            if np.any(up) and np.any(down):
                gaps.append(np.mean(v["raw_bias_dph"][up]) - np.mean(v["raw_bias_dph"][down]))
                var.append(np.mean(v["bias_se_dph"][up] ** 2) + np.mean(v["bias_se_dph"][down] ** 2))
        if not gaps:
            return []
        w = 1.0 / np.asarray(var)
        gap = float(np.sum(w * np.asarray(gaps)) / np.sum(w))
        half = 1.959963984540054 / math.sqrt(float(np.sum(w)))
        return [Result("verify_hysteresis_dph", gap, ci95=(gap - half, gap + half))]

    def _hyst_fits(self, p: dict[str, np.ndarray], order: int):
        """Heating minus cooling at the same temperature, of the bias and (with the table turning) of
        the scale factor, each beside its PLL-trail term (bench.analysis.thermal_ramp.branch_hysteresis):
        (the bias's Hysteresis, (sf gap ppm, its interval) or None), or None when the cycle is too short."""
        heating = p["branch"] == 0
        kw = dict(t_ref_c=REF_TEMPERATURE_C, guard_c=float(self.hyst_guard_degc))
        rate = p["f_rate_hz_s"] if self.hyst_rate_term else None
        try:
            hb = branch_hysteresis(p["frequency_c"], p["bias_dph"], p["bias_se_dph"], heating, rate, order=order, **kw)
        except ValueError:  # too few points beyond the guard (a short cycle): recorded NOT_MEASURED
            return None
        sf_gap = None
        if "sf" in p and len(p["sf"]) == len(heating):
            hs = branch_hysteresis(p["frequency_c"], p["sf"], p["sf_se"], heating, rate, order=1, **kw)
            sf25 = float(np.mean(p["sf"]))
            sf_gap = (hs.gap / sf25 * 1e6, (hs.gap_ci95[0] / sf25 * 1e6, hs.gap_ci95[1] / sf25 * 1e6))
        return hb, sf_gap

    def _hysteresis(self, fits) -> list[Result]:
        """The hysteresis fits' results (_hyst_fits; none for a cycle too short)."""
        if fits is None:
            return []
        hb, sf_gap = fits
        out = [Result("bias_hysteresis_dph", hb.gap, ci95=hb.gap_ci95)]
        if self.hyst_rate_term:
            out.append(Result("bias_per_freq_rate_dph_s_per_hz", hb.rate_coeff, ci95=hb.rate_coeff_ci95))
        if sf_gap is not None:
            out.append(Result("sf_hysteresis_ppm", float(sf_gap[0]), ci95=(float(sf_gap[1][0]), float(sf_gap[1][1]))))
        return out

    def figures(self, data) -> list:
        """The temperatures, the frequency by branch, the bias against each thermometer and the verification."""
        from procedures.figures.thermal_ramp import fit_figures, temperature_figure

        return temperature_figure(self, data) + fit_figures(self, data)
