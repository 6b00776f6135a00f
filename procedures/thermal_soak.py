"""thermal-soak: the unit's bias and resonator frequency at set points over a temperature range,
each recorded once the unit has settled, with polynomial fits against temperature
(docs/chamber.md, "The soak method").

Steps: excite and hold the amplitude; then for each set point (low to high, `points` of them):
the chamber's set point, windows of `settle_window_s` until the resonator frequency's drift
between consecutive windows stays below `settle_ppm_per_min` for `settle_windows` windows (the
unit's own thermometer, judged from its readings, not a fixed time), then a static record of
`record_s` with the chamber's part (case) temperature read at its start and end.  The analysis
takes each record's bias (bench.analysis.cvg_rate.static_bias) and mean frequency (batch means)
and fits each against the case temperature (bench.analysis.thermal_fit: weighted least squares,
the order by BIC, 95 % intervals).  With `compensate` the thermal trim (bias against the frequency's
offset from REF_FREQ_HZ) goes into the FPGA, and `verify_points` records between the set points
read what it leaves (docs/chamber.md, "The soak's trims")."""

from __future__ import annotations

import math
import threading
from typing import Any

import numpy as np

from bench.analysis.cvg_rate import static_bias
from bench.analysis.thermal_fit import ThermalFit, batch_mean, fit_temperature_polynomial
from bench.clock import Deadline
from bench.engine import Demand, Measurement, Param, Procedure, Result, step
from bench.streams import Column, StreamSchema, declare
from drivers.fpga.stream import STREAM_SCHEMA as FPGA

from .cvg_output import MODES, UNSTATED_BIAS_NO_TRUTH, CvgOutput, static_bias_truth

#: a settled record's columns, shared by the soak's windows and both procedures' verification records
SETTLED_RECORD_COLUMNS = (
    Column("t_start_s", "s"), Column("t_end_s", "s"), Column("setpoint_c", "degC"),
    Column("air_c", "degC", doc="chamber air at the record's start and end (mean)"),
    Column("part_c", "degC", doc="the part thermocouple on the unit's case (mean of start and end)"),
    Column("settle_s", "s", doc="time from the set point to the record's start"),
    Column("ref_freq_hz", "Hz", doc="the FPGA's REF_FREQ_HZ (the stream's freq_ctrl is relative to it)"),
    Column("mode", "1", "i8", legend={0: "whole-angle", 1: "force-to-rebalance"}),
    Column("scale_factor", "1"),
)
#: the bias trim in force during a verification record
BIAS_TRIM_COLUMNS = (
    Column("trim_bias_dph", "deg/h", doc="TRIM_BIAS_DPH in force during the record (0: no thermal trim)"),
    Column("trim_bias_dph_per_hz", "deg/h/Hz", doc="TRIM_BIAS_DPH_PER_HZ in force during the record"),
)

WINDOWS = declare(StreamSchema("thermal_soak_windows", "thermal-soak", SETTLED_RECORD_COLUMNS))

VERIFY = declare(StreamSchema("thermal_soak_verify", "thermal-soak", SETTLED_RECORD_COLUMNS + BIAS_TRIM_COLUMNS))

REF_TEMPERATURE_C = 25.0


def write_thermal_trim(ctx, registers: dict[str, float]) -> None:
    """The thermal trim registers (in the order given) into the FPGA, then TRIM_EN's TRIM_THERMAL bit (RAM
    only: the line commits trims to NVM for PASS units); the registers as they were before, TRIM_EN with
    them, are restored at the run's end (in reverse order)."""
    from drivers.fpga import protocol as fp

    fpga = ctx.devices.fpga
    names = ("TRIM_EN", *registers)
    before = {n: fpga.read_register(n) for n in names}

    def restore() -> None:
        if fpga.connected:
            for n in names[::-1]:
                fpga.write_register(n, before[n])

    ctx.defer(restore, "restore the thermal trim registers")
    for name, value in registers.items():
        fpga.write_register(name, value)
    fpga.write_register("TRIM_EN", int(before["TRIM_EN"]) | fp.TRIM_THERMAL)


def _verifying(proc) -> bool:
    return proc.verify_points > 0


def _trimming(proc) -> bool:
    return proc.verify_points > 0 or bool(proc.compensate)


def _pair(interval) -> tuple[float, float]:
    return float(interval[0]), float(interval[1])


def _f0_tc_truth(truth: dict[str, float]) -> float:
    """The World's frequency temperature coefficient (0 for a unit without error sources)."""
    return truth.get("err_freq_tc_ppm_k", 0.0)


def _f0_at_25c_truth(truth: dict[str, float]) -> float:
    """The frequency the FPGA's PLL runs the unit at, at the reference temperature: the natural
    frequency (the World's truth keeps the reference values under `<key>_ref` when the unit is
    elsewhere, simulators/physics/errors.py) plus, with the wave held in force-to-rebalance, the
    held wave's split, cubic stiffness and readout-phase detuning (`drive_freq_offset_hz`,
    simulators/physics/drive_frequency.py; docs/chamber.md, "The frequency the loops run at")."""
    return (truth["f0_hz"] + truth.get("freq_offset_hz_ref", truth["freq_offset_hz"])
            + truth.get("drive_freq_offset_hz", 0.0))


class ThermalChamber(CvgOutput):
    """Params and steps the chamber procedures share (thermal-soak, thermal-ramp): the range, the
    settle judgement from the resonator frequency, the fits' settings, the excitation step."""

    requires = ("fpga", "chamber")
    kinds = ("hrg", "mems-ring")  # the FPGA holds either in force-to-rebalance (sim-mems-thermal)

    t_low_degc = Param(-40.0, unit="degC", low=-100.0, high=200.0, doc="lowest set point")
    t_high_degc = Param(85.0, unit="degC", low=-100.0, high=200.0, doc="highest set point")
    ramp_degc_per_min = Param(3.0, unit="degC/min", low=0.1, high=50.0, doc="the chamber's set-point ramp limit")
    settle_window_s = Param(120.0, unit="s", low=5.0, high=3600.0,
                            doc="window whose mean frequency is compared with the one before")
    settle_ppm_per_min = Param(0.05, unit="ppm/min", low=1e-4, high=100.0,
                               doc="settled when the frequency drifts less than this (0.05 ppm/min: ~1 mK/min "
                                   "at fused silica's 55 ppm/K)")
    settle_windows = Param(2, low=1, high=100, doc="consecutive windows below the drift threshold")
    settle_timeout_s = Param(6 * 3600.0, unit="s", low=60.0, high=1e6, doc="longest wait at one set point")
    unlocked_windows = Param(4, low=1, high=1000,
                             doc="settle windows in a row that may end with the FPGA's PLL unlocked before the "
                                 "unit is given up (its loops have lost the wave: no drift judgement can settle)")
    batches = Param(10, low=2, high=1000, doc="batches of each record for its intervals")
    max_order = Param(3, low=0, high=6, doc="highest polynomial order the fits try")
    resolution_degc = Param(0.1, unit="degC", low=0.0, high=5.0,
                            doc="the part thermocouple's display step: its error (step / sqrt 12) enters the fits "
                                "as an effective variance (bench.analysis.thermal_fit)")
    stream_hz = Param(10.0, unit="Hz", low=0.01, high=1e6, doc="FPGA stream rate during the run (boxcar-decimated)")
    scale_factor = Param(0.0, low=-1e6, high=1e6,
                         doc="output per input rate (from cvg-scale-factor); 0: the mode's nominal one "
                             "(force-to-rebalance: the FPGA's FTR_GAIN x bryan_factor; whole-angle: -bryan_factor)")
    bryan_factor = Param(0.0, low=0.0, high=1.0,
                         doc="nominal K: whole-angle's nominal scale factor is -K (0: the station's nominal K)")
    nominal_params = {"bryan_factor": "bryan_factor"}

    def demands(self) -> list[Demand]:
        return []

    # --- the frequency the stream carries, kept for the settle judgement -----------------------
    def _collect(self, block: np.ndarray) -> None:
        """Stream subscriber: accumulate freq_ctrl for the current settle window."""
        f = FPGA.columns_of(block, "freq_ctrl")
        with self._lock:
            self._f_sum += float(np.sum(f))
            self._f_n += len(f)

    def _window_freq(self, ctx, seconds: float) -> float:
        """Mean freq_ctrl (Hz, relative to REF_FREQ_HZ) over the next `seconds` of bench time."""
        fpga = ctx.devices.fpga
        fpga.sync()
        with self._lock:
            self._f_sum, self._f_n = 0.0, 0
        ctx.sleep(seconds)
        fpga.sync()
        with self._lock:
            if self._f_n == 0:
                raise RuntimeError(f"no stream sample in a {seconds:g} s settle window")
            return self._f_sum / self._f_n

    @step("Excite and hold the amplitude", uses=("fpga",), shares=("chamber",))
    def excite(self, ctx):
        if self.t_high_degc <= self.t_low_degc:
            raise ValueError(f"t_high_degc={self.t_high_degc:g} must be above t_low_degc={self.t_low_degc:g}")
        self._lock = threading.Lock()
        self._f_sum, self._f_n = 0.0, 0
        ctx.subscribe(ctx.devices.fpga, self._keep_latest)
        ctx.subscribe(ctx.devices.fpga, self._collect)
        self._start_output(ctx)
        self._start_loops(ctx)
        self._hold_amplitude(ctx)
        chamber = ctx.devices.chamber
        ctx.shared(lambda: (chamber.stop_profile(), chamber.set_ramp_rate(self.ramp_degc_per_min)), "chamber ready")
        if not ctx.in_batch:  # a batch's chamber goes to ambient once, when the batch ends (bench.slots)
            ctx.defer(lambda: chamber.set_setpoint(REF_TEMPERATURE_C) if chamber.connected else None,
                      "chamber set point back to 25 degC")

    def _chamber_status(self, ctx) -> Any:
        """The chamber's air and part readings, read once for a batch (every slot gets the same)."""
        return ctx.shared(ctx.devices.chamber.status, "chamber reading")

    def _settle_at(self, ctx, setpoint_c: float, ref_hz: float) -> float:
        """Write the set point, then wait until the frequency's drift between consecutive windows
        stays below settle_ppm_per_min for settle_windows windows; the seconds it took.  In a batch
        the set point is written once and every unit waits until all of them have settled (each
        judged from its own frequency: the slowest sets the pace)."""
        chamber = ctx.devices.chamber
        t_set = ctx.shared(lambda: (chamber.set_setpoint(setpoint_c), ctx.clock.now())[1], f"set point {setpoint_c:g}")
        from drivers.fpga import protocol as fp

        prev, quiet, unlocked = None, 0, 0
        pauses = Deadline(ctx.clock, self.settle_timeout_s)  # a pause (real time) is not settling time
        while min(ctx.gather(quiet, f"settled at {setpoint_c:g}")) < self.settle_windows:
            if ctx.clock.now() - t_set - pauses.paused_since_s() > self.settle_timeout_s:
                raise TimeoutError(f"set point {setpoint_c:g} degC: the frequency still drifts after "
                                   f"{self.settle_timeout_s:g} s (threshold {self.settle_ppm_per_min:g} ppm/min)")
            f = self._window_freq(ctx, self.settle_window_s)
            # a unit whose loops lost the wave never settles: give it up (a batch goes on without it)
            # rather than wait out settle_timeout_s
            unlocked = 0 if int(ctx.devices.fpga.read_register("STATUS")) & fp.ST_PLL_LOCKED else unlocked + 1
            if unlocked >= self.unlocked_windows:
                raise RuntimeError(f"set point {setpoint_c:g} degC: the PLL was unlocked at the end of {unlocked} "
                                   f"settle windows in a row: the unit's loops have lost the wave")
            if prev is not None:
                drift = (f - prev) / (ref_hz + f) * 1e6 / (self.settle_window_s / 60.0)
                quiet = quiet + 1 if abs(drift) < self.settle_ppm_per_min else 0
            prev = f
        return ctx.clock.now() - t_set


class ThermalSoak(ThermalChamber, Procedure):
    """Bias and resonator frequency against temperature from set points with settled soaks."""

    name = "thermal-soak"
    windows_schema = WINDOWS

    points = Param(6, low=3, high=50, doc="set points from t_low_degc to t_high_degc, equally spaced (3 or more: "
                                         "a line with a degree of freedom left for its interval)")
    record_s = Param(300.0, unit="s", low=1.0, high=1e5, doc="static record once settled")
    compensate = Param(False, doc="the thermal trim (bias against the resonator frequency's offset from "
                                  "REF_FREQ_HZ, a straight line through the settled records) into the FPGA's "
                                  "registers before the verification (RAM; the line's gated trims take it to NVM)")
    verify_points = Param(0, low=0, high=49,
                          doc="settled verification records after the soak, at the middles between consecutive "
                              "set points (highest first, each reached from above), with the trim in force when "
                              "`compensate`: the compensated residual bias between the calibration points")

    measurements = (
        Measurement("f0_tc_ppm_k", "ppm/K", "resonator frequency's temperature coefficient at 25 degC "
                    "(fit slope over the fitted frequency there)", truth=_f0_tc_truth),
        Measurement("f0_at_25c_hz", "Hz", "resonator frequency at 25 degC from the fit (the PLL's: the held "
                    "wave's at the AGC's amplitude)", truth=_f0_at_25c_truth),
        Measurement("bias_tc_dph_k", "deg/h/K", "bias's temperature slope at 25 degC from the fit"),
        Measurement("bias_at_25c_dph", "deg/h", "bias at 25 degC from the fit (the wave's angle held in "
                    "force-to-rebalance; in whole-angle it precesses through the soak)", truth=static_bias_truth,
                    no_truth=UNSTATED_BIAS_NO_TRUTH),
        Measurement("bias_fit_order", "", "polynomial order of the bias fit (lowest BIC)",
                    no_interval="an order chosen by a criterion"),
        Measurement("f0_fit_order", "", "polynomial order of the frequency fit (lowest BIC)",
                    no_interval="an order chosen by a criterion"),
        Measurement("bias_fit_rms_dph", "deg/h", "rms residual of the bias fit",
                    no_interval="a residual"),
        Measurement("settle_mean_s", "s", "mean time from a set point to its settled record",
                    no_interval="a time the run took"),
        Measurement("thermal_bias_dph", "deg/h", "thermal trim TRIM_BIAS_DPH: the bias at the FPGA's REF_FREQ_HZ "
                    "(a straight line of the settled records' bias against their frequency's offset from it)",
                    when=_trimming, when_doc="compensate or verify_points > 0"),
        Measurement("thermal_bias_dph_per_hz", "deg/h/Hz", "thermal trim TRIM_BIAS_DPH_PER_HZ: that line's slope",
                    when=_trimming, when_doc="compensate or verify_points > 0"),
        Measurement("verify_residual_dph", "deg/h", "rms bias left at the verification points by the thermal trim "
                    "(the FPGA's compensated output with `compensate`, else the trim applied in the analysis)",
                    no_interval="a residual", when=_verifying, when_doc="verify_points > 0"),
        Measurement("verify_noise_dph", "deg/h", "rms of the verification records' own bias standard errors "
                    "(what the unit's noise allows a residual)", no_interval="a noise level", when=_verifying,
                    when_doc="verify_points > 0"),
        Measurement("verify_allowed_dph", "deg/h", "what the unit's noise and the trim fit's interval allow the "
                    "compensated residual: rms over the verification points of the record's bias standard error "
                    "and the trim line's standard error at the point's frequency, in quadrature",
                    no_interval="a noise level", when=_verifying, when_doc="verify_points > 0"),
    )

    def setpoints_c(self) -> np.ndarray:
        return np.linspace(self.t_low_degc, self.t_high_degc, int(self.points))

    @step("Set points, settle and record", uses=("fpga",), shares=("chamber",))
    def soak(self, ctx):
        fpga = ctx.devices.fpga
        ref_hz = float(fpga.read_register("REF_FREQ_HZ"))
        code = MODES.index(self._mode)
        sf = self._scale_factor(ctx)
        sps = self.setpoints_c()
        for i, sp in enumerate(sps):
            settle_s = self._settle_at(ctx, float(sp), ref_hz)
            s0 = self._chamber_status(ctx)
            t0, t1 = self._record_window(ctx, self.record_s, f"set point {sp:g} degC record")
            s1 = self._chamber_status(ctx)
            row = [t0, t1, sp, 0.5 * (s0.air_c + s1.air_c), 0.5 * (s0.part_c + s1.part_c), settle_s, ref_hz, code, sf]
            ctx.record(WINDOWS, WINDOWS.names, np.array([row]))
            ctx.log.info(f"set point {sp:g} degC: settled after {settle_s:.0f} s, case {row[4]:.1f} degC")
            ctx.progress((i + 1) / len(sps), f"set point {i + 1} / {len(sps)}")

    def verify_setpoints_c(self) -> np.ndarray:
        """verify_points of the middles between consecutive set points, evenly picked, highest first."""
        sps = self.setpoints_c()
        mids = 0.5 * (sps[:-1] + sps[1:])
        n = min(int(self.verify_points), len(mids))
        if n == 0:
            return mids[:0]
        return mids[np.round(np.linspace(0, len(mids) - 1, n)).astype(int)][::-1]

    @step("Thermal trim and verification between the set points", uses=("fpga",), shares=("chamber",))
    def verify(self, ctx):
        if not self.verify_points:
            if self.compensate:
                ctx.log.info("compensate without verify_points: the trim is reported for the line, not tried")
            return
        fpga = ctx.devices.fpga
        ref_hz = float(fpga.read_register("REF_FREQ_HZ"))
        code, sf = MODES.index(self._mode), self._scale_factor(ctx)
        trim = (0.0, 0.0)
        if self.compensate:
            line = self.trim_line(self.points_table(ctx.data()))
            trim = (float(line.coeffs[0]), float(line.coeffs[1]))
            self._write_trim(ctx, trim)
        for sp in self.verify_setpoints_c():  # the soak ended at t_high: each point from above
            settle_s = self._settle_at(ctx, float(sp), ref_hz)
            s0 = self._chamber_status(ctx)
            t0, t1 = self._record_window(ctx, self.record_s, f"verification {sp:g} degC record")
            s1 = self._chamber_status(ctx)
            row = [t0, t1, sp, 0.5 * (s0.air_c + s1.air_c), 0.5 * (s0.part_c + s1.part_c), settle_s, ref_hz, code, sf,
                   *trim]
            ctx.record(VERIFY, VERIFY.names, np.array([row]))

    def _write_trim(self, ctx, trim: tuple[float, float]) -> None:
        """The bias trim into the FPGA's registers and TRIM_EN's TRIM_THERMAL bit (RAM only: the line
        commits trims to NVM for PASS units); the registers before are restored at the end."""
        write_thermal_trim(ctx, {"TRIM_BIAS_DPH": trim[0], "TRIM_BIAS_DPH_PER_HZ": trim[1],
                                 # the soak measures no scale factor: no trim of it
                                 "TRIM_SF_PPM": 0.0, "TRIM_SF_PPM_PER_HZ": 0.0})
        ctx.log.info(f"thermal trim on: {trim[0]:.4g} deg/h at REF_FREQ_HZ, {trim[1]:.4g} deg/h/Hz")

    def trim_line(self, p: dict[str, np.ndarray]) -> ThermalFit:
        """The thermal trim: a straight line of the records' bias against their frequency's offset from
        REF_FREQ_HZ (the FPGA's trim is that line), the frequencies' own errors carried."""
        if not np.allclose(p["ref_hz"], p["ref_hz"][0], rtol=0.0, atol=1e-6):
            raise RuntimeError("REF_FREQ_HZ changed during the soak: one thermal trim cannot hold it")
        return fit_temperature_polynomial(p["f_offset_hz"], p["bias_dph"], p["bias_se_dph"], max_order=1, min_order=1,
                                          t_ref_c=0.0, sigma_t_c=float(np.median(p["f0_se_hz"])))

    def verification(self, data) -> dict[str, np.ndarray]:
        """The verification records' points (points_table of VERIFY) and raw_bias_dph: the unit's bias
        before any trim (the record's plus the trim in force during it)."""
        v = self.points_table(data, VERIFY)
        vt = data.table(VERIFY.name)
        v["raw_bias_dph"] = v["bias_dph"] + vt["trim_bias_dph"] + vt["trim_bias_dph_per_hz"] * v["f_offset_hz"]
        return v

    @step("Fits against temperature", uses=())
    def estimate(self, ctx):
        for res in self.analysis(ctx.data()):
            ctx.report(res)

    def points_table(self, data, schema: StreamSchema = WINDOWS) -> dict[str, np.ndarray]:
        """Each record's case temperature, bias (deg/h) and frequency (Hz) with standard errors, the
        REF_FREQ_HZ it was taken at and the frequency's offset from it (schema: WINDOWS or VERIFY)."""
        win = data.table(schema.name)
        fpga = data.table("fpga")
        t = fpga["t_s"]
        earth_dph = self.earth_rate_on_axis_dph(data)
        rows = []
        for t0, t1, part, ref, mode, sf in zip(win["t_start_s"], win["t_end_s"], win["part_c"], win["ref_freq_hz"],
                                               win["mode"], win["scale_factor"], strict=True):
            sel = (t > t0) & (t <= t1)
            name = MODES[int(mode)]
            y = fpga["rate_out_dps"][sel] if name == "force-to-rebalance" else fpga["angle_out_deg"][sel]
            b = static_bias(t[sel], y, mode=name, scale_factor=float(sf), earth_rate_dph=earth_dph,
                            n_batches=self.batches)
            f, f_se = batch_mean(fpga["freq_ctrl"][sel], self.batches)
            rows.append((part, b.bias_dph, b.sigma_dph, ref + f, f_se, ref, f))
        a = np.array(rows, dtype=float).reshape(-1, 7)
        return {"part_c": a[:, 0], "bias_dph": a[:, 1], "bias_se_dph": a[:, 2], "f0_hz": a[:, 3], "f0_se_hz": a[:, 4],
                "ref_hz": a[:, 5], "f_offset_hz": a[:, 6]}

    def fits(self, data) -> tuple[dict[str, np.ndarray], ThermalFit, ThermalFit]:
        """The points, the bias fit and the frequency fit."""
        p = self.points_table(data)
        if len(p["part_c"]) < 2:
            raise RuntimeError(f"{len(p['part_c'])} settled record(s): a fit needs 2 or more set points")
        kw = dict(max_order=int(self.max_order), t_ref_c=REF_TEMPERATURE_C,
                  sigma_t_c=self.resolution_degc / math.sqrt(12.0))
        bias = fit_temperature_polynomial(p["part_c"], p["bias_dph"], p["bias_se_dph"], **kw)
        f0 = fit_temperature_polynomial(p["part_c"], p["f0_hz"], p["f0_se_hz"], **kw)
        return p, bias, f0

    def _linear(self, data, key: str) -> ThermalFit:
        p = self.points_table(data)
        y, se = (p["f0_hz"], p["f0_se_hz"]) if key == "f0" else (p["bias_dph"], p["bias_se_dph"])
        return fit_temperature_polynomial(p["part_c"], y, se, max_order=1, min_order=1, t_ref_c=REF_TEMPERATURE_C,
                                          sigma_t_c=self.resolution_degc / math.sqrt(12.0))

    def analysis(self, data) -> list[Result]:
        """The fits' results from a recorded run's `thermal_soak_windows` and `fpga` streams."""
        _, bias, f0 = self.fits(data)
        f25 = float(f0.coeffs[0])
        out = [
            Result("f0_at_25c_hz", f25, ci95=_pair(f0.ci95[0])),
            Result("bias_at_25c_dph", float(bias.coeffs[0]), ci95=_pair(bias.ci95[0])),
            Result("bias_fit_order", float(bias.order)),
            Result("f0_fit_order", float(f0.order)),
            Result("bias_fit_rms_dph", float(np.sqrt(np.mean(bias.residuals**2)))),
        ]
        # a slope where the BIC kept none: the straight line's, with its interval (holding 0)
        f0_s, bias_s = (fit if fit.order >= 1 else self._linear(data, key) for fit, key in ((f0, "f0"), (bias, "bias")))
        lo, hi = f0_s.ci95[1]
        out.append(Result("f0_tc_ppm_k", float(f0_s.coeffs[1] / f25 * 1e6),
                          ci95=(float(lo / f25 * 1e6), float(hi / f25 * 1e6))))
        out.append(Result("bias_tc_dph_k", float(bias_s.coeffs[1]), ci95=_pair(bias_s.ci95[1])))
        win = data.table(WINDOWS.name)
        out.append(Result("settle_mean_s", float(np.mean(win["settle_s"]))))
        if _trimming(self):
            trim = self.trim_line(self.points_table(data))
            out += [Result("thermal_bias_dph", float(trim.coeffs[0]), ci95=_pair(trim.ci95[0])),
                    Result("thermal_bias_dph_per_hz", float(trim.coeffs[1]), ci95=_pair(trim.ci95[1]))]
            if self.verify_points:
                v = self.verification(data)
                out += [Result("verify_residual_dph",
                               float(np.sqrt(np.mean((v["raw_bias_dph"] - trim(v["f_offset_hz"])) ** 2)))),
                        Result("verify_noise_dph", float(np.sqrt(np.mean(v["bias_se_dph"] ** 2)))),
                        Result("verify_allowed_dph", float(np.sqrt(np.mean(
                            v["bias_se_dph"] ** 2 + trim.se_at(v["f_offset_hz"]) ** 2))))]
        return out

    def figures(self, data) -> list:
        """Frequency and bias against the case temperature with their fits and residuals."""
        from procedures.figures.thermal_soak import fit_figures, temperature_figure

        return temperature_figure(self, data) + fit_figures(self, data)
