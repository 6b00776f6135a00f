"""HRG damping non-uniformity: the patent's free decay on a rate table, its fit, the compensation
and its verification (issue 8; PHYSICS.md section 3).

Steps: excite and hold the amplitude; spin the table; wait until the rate is stable; cut the
drive; record the decay; compute E, theta and the quadrature; fit theta_tau, Delta(1/tau), tau;
write the coefficients to the FPGA's drift-compensation registers and measure the drift against
the wave angle with the compensation off and on (whole-angle mode turns the wave through every
angle).  The decay and verification windows are recorded as the `damping_windows` stream, so
`analysis(data)` re-fits a recorded run with the same code.
"""

from __future__ import annotations

import math
import threading
from typing import Any

import numpy as np

from bench.analysis.axes import AXIS_PERIOD_DEG
from bench.analysis.damping import METHODS, MODELS, fit_angle_harmonics, fit_free_decay
from bench.analysis.slow_model import orbit_elements
from bench.engine import Measurement, Param, Procedure, Result, recorded_text, step
from bench.engine.recording import in_spans
from bench.streams import Column, StreamSchema, declare
from drivers.fpga.stream import STREAM_SCHEMA as FPGA

from .hrg_excitation import (
    SPLIT_LEARN_DEG,
    HrgExcitation,
    refuse_above_precession_limit,
    saturation_refusal,
    settle_time_s,
)

WINDOWS = "damping_windows"
DECAY, VERIFY_OFF, VERIFY_ON = 0.0, 1.0, 2.0
WINDOW_COLUMNS = declare(StreamSchema(WINDOWS, "hrg-damping", (
    Column("kind", "1", "i8", legend={0: "decay", 1: "verify_off", 2: "verify_on"}),
    Column("t_start_s", "s"), Column("t_end_s", "s")))).names
REF = "damping_reference"  # the reference frequency held during the decay, for Q = pi f0 tau
declare(StreamSchema(REF, "hrg-damping", (Column("t_s", "s"), Column("f0_hz", "Hz"))))
# the fits' curves, declared like stream columns: the report's axes take their quantities and units
_T = Column("t_s", "s", quantity="time t")
_THETA = Column("theta_deg", "deg", quantity="wave angle θ")
declare(StreamSchema("hrg-damping theta", "hrg-damping", (_T, _THETA)))
declare(StreamSchema("hrg-damping quadrature", "hrg-damping", (
    _T, Column("quadrature_rel", "1", quantity="quadrature k/a"))))
declare(StreamSchema("hrg-damping energy", "hrg-damping", (
    _T, Column("energy", "1", quantity="energy E"), Column("energy_fit", "1", quantity="fitted energy E"))))
declare(StreamSchema("hrg-damping residuals", "hrg-damping", (
    _T, Column("residual_ln_e", "1", quantity="residual ln E"))))
for _name in ("before", "after"):
    declare(StreamSchema(f"hrg-damping drift {_name}", "hrg-damping", (
        _THETA, Column("drift_dph", "deg/h", quantity="drift, output-referred"))))
_TAP = ("t_s", "cx", "sx", "cy", "sy")  # the FPGA stream's columns a tap keeps, in this order
#: the rows a tap keeps (not a recorded stream: read by name, as the FPGA stream they come from)
TAP = StreamSchema("hrg_damping_tap", "fpga", tuple(FPGA.columns[FPGA.index(c)] for c in _TAP))
_Q = ("cx", "sx", "cy", "sy")
_MAX_CURVE_POINTS = 2000


class _StreamTap:
    """Keeps the FPGA stream's named columns (t_s, cx, sx, cy, sy unless told) while `on` (runs on
    the link's reader thread: appends only)."""

    def __init__(self, columns: tuple[str, ...] = _TAP) -> None:
        self.columns = tuple(columns)
        self._positions = FPGA.indices(*self.columns)  # looked up by name once, not per block
        self.on = False
        self._rows: list[np.ndarray] = []
        self._lock = threading.Lock()

    def __call__(self, block: np.ndarray) -> None:
        if self.on:
            rows = block[:, self._positions]
            with self._lock:
                self._rows.append(rows)

    def stop(self) -> None:
        """Keep nothing more and drop what is kept (the run has ended)."""
        self.on = False
        with self._lock:
            self._rows.clear()

    def take(self, t_start_s: float, t_end_s: float) -> np.ndarray:
        with self._lock:
            rows = np.vstack(self._rows) if self._rows else np.empty((0, len(self.columns)))
            self._rows.clear()
        t_s = TAP.column(rows, "t_s")
        return rows[(t_s > t_start_s) & (t_s <= t_end_s)]


def _decay_columns(rows: np.ndarray) -> list[np.ndarray]:
    """fit_free_decay's arguments (t_s, cx, sx, cy, sy) from tap rows, by name."""
    return [TAP.column(rows, c) for c in ("t_s", *_Q)]


def _thin(*arrays: np.ndarray) -> list[np.ndarray]:
    """Every k-th point so that plots get at most _MAX_CURVE_POINTS."""
    k = max(1, int(math.ceil(len(arrays[0]) / _MAX_CURVE_POINTS)))
    return [np.asarray(a)[::k] for a in arrays]


def _compensating(proc: Any) -> bool:
    return bool(proc.compensate)


#: the harmonics of the wave angle fitted in the verification's drift (the angle model's mean + these)
DRIFT_ORDERS = (4, 8, 12)


#: why the mean drift is compared with no truth (docs/damping_drift.md, "The mean drift against a truth of 0")
MEAN_DRIFT_NO_TRUTH = (
    "not compared: one record's mean carries the loops' random walk (sd 0.013 deg/h over seeds at 90 s; "
    "docs/damping_drift.md)")


def _drift_declarations() -> tuple[Measurement, ...]:
    """The verification's drift measurements (only with `compensate` on), output-referred."""
    when, when_doc = _compensating, "compensate"
    out = []
    for name, words in (("before", "compensation off"), ("after", "compensation on")):
        out.append(Measurement(f"drift_{name}_dph", "deg/h",
                               f"4 theta drift amplitude, {words} (angle-record fit of mean + 4 theta)",
                               truth="drift_before_dph" if name == "before" else None, when=when, when_doc=when_doc))
        out.append(Measurement(f"drift_{name}_mean_dph", "deg/h",
                               f"mean drift, {words} (angle-record fit of mean + 4, 8, 12 theta)",
                               when=when, when_doc=when_doc, no_truth=MEAN_DRIFT_NO_TRUTH))
        for m in (4, 8, 12):
            truth = f"drift_{name}_{m}theta_dph" if (name, m) != ("after", 4) else None
            out.append(Measurement(f"drift_{name}_{m}theta_dph", "deg/h",
                                   f"{m} theta drift amplitude, {words} (angle-record fit of mean + 4, 8, 12 theta)",
                                   truth=truth, when=when, when_doc=when_doc))
            # the damping drift's 4 theta term is sin 4(theta - theta_tau): its phase is the damping axis
            out.append(Measurement(f"drift_{name}_{m}theta_phase_deg", "deg",
                                   f"phase of the {m} theta drift term, amplitude sin {m}(theta - phase), {words} "
                                   "(interval: the whole period when the amplitude's holds 0)",
                                   truth="theta_tau_deg" if (name, m) == ("before", 4) else None,
                                   when=when, when_doc=when_doc, period=360.0 / m))
        out.append(Measurement(f"drift_{name}_rest_rms_dph", "deg/h",
                               f"rms of the drift_block_s block rates beyond the angle fit's model, {words} (noise)",
                               when=when, when_doc=when_doc,
                               no_interval="a statistic of this record, not an estimate of a parameter: no interval"))
    out.append(Measurement("drift_reduction_ratio", "", "drift_before_dph / drift_after_dph", when=when,
                           when_doc=when_doc, no_interval="a ratio whose denominator's interval may hold 0: no "
                           "interval; the two drifts have theirs"))
    out.append(Measurement("drift_after_4theta_expected_dph", "deg/h",
                           "4 theta drift the decay fit's own error leaves after compensation (rms; ci95 0 to its "
                           "95 % bound)", when=when, when_doc=when_doc))
    return tuple(out)


def block_drift(t_s: np.ndarray, theta_rad: np.ndarray, block_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Wave angle rate by least-squares slopes over blocks of block_s: (theta mid-block, rate)."""
    theta = np.unwrap(4.0 * theta_rad) / 4.0
    edges = np.arange(t_s[0], t_s[-1] + 1e-12, block_s)
    mids, rates = [], []
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        sel = (t_s >= a) & (t_s < b)
        if sel.sum() < 3:
            continue
        slope, icpt = np.polyfit(t_s[sel] - a, theta[sel], 1)
        mids.append(icpt + slope * 0.5 * (b - a))
        rates.append(slope)
    return np.asarray(mids), np.asarray(rates)


class HrgDamping(HrgExcitation, Procedure):
    """HRG damping non-uniformity from a free decay on a rate table (the patent), with compensation."""

    name = "hrg-damping"
    #: the record windows' stream and the decay window's kind in it (its figures read them here)
    windows_stream = WINDOWS
    decay_kind = DECAY
    requires = ("table", "frontend", "fpga")
    kinds = ("hrg",)

    rate_dps = Param(500.0, unit="deg/s", low=-1000.0, high=1000.0, doc="table rate during the decay (patent: 500)")
    accel_dps2 = Param(200.0, unit="deg/s^2", low=0.1, high=10000.0, doc="table acceleration")
    record_s = Param(900.0, unit="s", low=1.0, high=100000.0, doc="record duration (about 3 tau)")
    stream_hz = Param(100.0, unit="Hz", low=0.1, high=1e6, doc="rate of the samples fitted (boxcar-decimated stream)")
    fit_method = Param("log-linear", choices=METHODS, doc="estimator (bench.analysis.damping)")
    fit_model = Param("exact", choices=MODELS, doc="energy model: quadrature-aware or the patent's")
    compensate = Param(True, doc="write the coefficients to the FPGA and verify the drift off and on")
    verify_rate_dps = Param(2.0, unit="deg/s", low=0.01, high=100.0, doc="whole-angle precession while verifying")
    verify_s = Param(90.0, unit="s", low=1.0, high=100000.0, doc="drift record per verification (off, on)")
    verify_settle_s = Param(0.0, unit="s", low=0.0, high=600.0,
                            doc="settling before each verification record; 0: from the loops' bandwidth and the "
                                "command (4.6 time constants of the slowest loop, plus the wave's turn of 22.5 deg "
                                "for the split observer before the first record)")
    drift_block_s = Param(1.0, unit="s", low=0.01, high=100.0,
                          doc="block of the drift rates plotted (the drift is fitted to the angle record itself)")
    bryan_factor = Param(0.0, unit="", low=0.0, high=1.0,
                         doc="K: refers the wave's drift to the gyro output (0: the station's nominal K)")
    nominal_params = {"bryan_factor": "bryan_factor"}

    measurements = (
        Measurement("quadrature_rel_max", "", "largest |quadrature| / amplitude over the decay record",
                    no_interval="a statistic of this record, not an estimate of a parameter: no interval"),
        Measurement("theta_tau_deg", "deg", "damping axis theta_tau in [0, 90)", truth="theta_tau_deg",
                    period=AXIS_PERIOD_DEG),
        Measurement("delta_inv_tau_per_s", "1/s", "damping anisotropy Delta(1/tau)", truth="delta_inv_tau_per_s"),
        Measurement("tau_s", "s", "mean amplitude decay time tau", truth="tau_s"),
        Measurement("q_factor", "", "quality factor pi f0 tau (f0: the reference frequency held during the decay)",
                    truth="q_factor"),
        Measurement("drift_predicted_dph", "deg/h", "damping drift amplitude Delta(1/tau) / 4K predicted by the fit",
                    truth="drift_predicted_dph"),
        *_drift_declarations(),
    )

    def __init__(self, params: dict[str, Any] | None = None) -> None:
        super().__init__(params)
        self._tap = _StreamTap()
        self._decay: np.ndarray | None = None
        self._fit = None
        self._spans: dict[float, Any] = {}

    def preflight(self, devices) -> None:
        """The verification's precession command within the FPGA's force limit (read-only)."""
        if self.compensate:
            refuse_above_precession_limit(self, devices, "verify_rate_dps", self.verify_rate_dps, "deg/s ")

    # --- helpers -----------------------------------------------------------------------------
    def _sample_period_s(self, ctx) -> float:
        return float(ctx.devices.fpga.read_register("SAMPLE_PERIOD_S"))

    def _decimate(self, rows: np.ndarray, period_s: float) -> np.ndarray:
        dec = max(1, int(round(1.0 / (self.stream_hz * period_s))))
        idx = np.rint(TAP.column(rows, "t_s") / period_s).astype(np.int64)
        return rows[idx % dec == 0]

    def _record(self, ctx, kind: float, duration_s: float, label: str) -> np.ndarray:
        """duration_s of the tap's rows to an absolute deadline (ctx.record_for), a pause inside
        excluded; the window goes to the raw file and the log says what the data hold."""
        fpga = ctx.devices.fpga
        fpga.sync()
        self._tap.take(-math.inf, -math.inf)  # drop anything older
        self._tap.on = True
        span = ctx.record_for(duration_s, label)
        fpga.sync()
        self._tap.on = False
        ctx.record(WINDOWS, WINDOW_COLUMNS, np.array([[kind, span.t_start_s, span.t_end_s]]))
        rows = self._tap.take(span.t_start_s, span.t_end_s)
        rows = rows[span.keep(TAP.column(rows, "t_s"))]
        self._spans[kind] = span
        self._refuse_saturation(span.t_start_s, span.t_end_s, label)
        return rows

    # --- steps -------------------------------------------------------------------------------
    @step("Excite and hold the amplitude", uses=("fpga",))
    def excite(self, ctx):
        fpga = ctx.devices.fpga
        ctx.subscribe(fpga, self._tap)
        ctx.subscribe(fpga, self._keep_latest)
        ctx.defer(self._tap.stop)
        self._start_loops(ctx)
        a = self._hold_amplitude(ctx)
        ctx.log.info(f"amplitude {a:.4f} held (setpoint {self.amplitude:g})")

    @step("Spin the table", uses=("table",))
    def spin(self, ctx):
        self._start_spin(ctx)

    @step("Wait for a stable rate", uses=("table",))
    def wait_stable(self, ctx):
        st = self._wait_stable(ctx)
        ctx.log.info(f"table stable at {st.rate_dps:.4f} deg/s")

    @step("Cut the drive", uses=("fpga", "frontend"))
    def cut_drive(self, ctx):
        self._cut_drive(ctx)

    @step("Record cx, sx, cy, sy", uses=("fpga",))
    def record(self, ctx):
        fpga = ctx.devices.fpga
        period = self._sample_period_s(ctx)
        dec = max(1, int(round(1.0 / (self.stream_hz * period))))
        old = int(fpga.read_register("STREAM_DECIMATION"))
        if dec != old:  # the FPGA streams at the requested rate (every dec-th sample) for the decay
            fpga.start_stream(dec)
        try:
            rows = self._record(ctx, DECAY, self.record_s, "free decay")
        finally:
            if dec != old:
                fpga.start_stream(old)
        self._decay = self._decimate(rows, period)
        ctx.log.info(recorded_text("free decay", TAP.column(self._decay, "t_s"), self._spans[DECAY]))

    @step("Compute E, theta and the quadrature", uses=())
    def elements(self, ctx):
        d = self._decay
        if d is None or len(d) < 8:
            raise RuntimeError(f"the decay record holds {0 if d is None else len(d)} samples; at least 8 are needed")
        el = orbit_elements(TAP.columns_of(d, *_Q))
        t_s = TAP.column(d, "t_s")
        t, th, k = _thin(t_s, np.unwrap(4 * el["theta_rad"]) / 4, el["k"] / np.maximum(el["a"], 1e-300))
        ctx.fit("hrg-damping theta", t_s=t, theta_deg=np.degrees(th))
        ctx.fit("hrg-damping quadrature", t_s=t, quadrature_rel=k)
        ctx.measure("quadrature_rel_max", float(np.max(np.abs(el["k"] / np.maximum(el["a"], 1e-300)))))

    @step("Fit the free-decay model", uses=("fpga",))
    def fit(self, ctx):
        d = self._decay
        fit = ctx.compute(fit_free_decay, *_decay_columns(d),  # abortable at once
                          method=self.fit_method, model=self.fit_model)
        self._fit = fit
        t, e, ef, r = _thin(fit.t_s, fit.energy, fit.energy_fit, fit.residuals_ln_e)
        ctx.fit("hrg-damping energy", t_s=t, energy=e, energy_fit=ef)
        ctx.fit("hrg-damping residuals", t_s=t, residual_ln_e=r)
        f0_hz = self._f0_hz(ctx)
        ctx.record(REF, ("t_s", "f0_hz"), np.array([[ctx.clock.now(), f0_hz]]))
        for res in self._decay_results(fit, f0_hz):
            ctx.report(res)
        ctx.log.info(fit.summary())

    @step("Stop the table", uses=("table",))
    def stop_table(self, ctx):
        """The verification turns the wave in whole-angle mode with the case at rest (a batch step
        with several gyros on the table: one stop for all)."""
        if not self.compensate:
            return
        table = ctx.devices.table
        table.stop(self.accel_dps2)
        table.wait_at_rest(timeout_s=self.rate_timeout_s + abs(self.rate_dps) / self.accel_dps2)

    @step("Compensate and verify", uses=("fpga",))
    def compensate_step(self, ctx):
        self._compensate(ctx)

    def _compensate(self, ctx):
        if not self.compensate:
            ctx.log.info("compensation not requested")
            return
        fit = self._fit
        fpga = ctx.devices.fpga
        fpga.set_drift_compensation(False, fit.delta_inv_tau_per_s, fit.theta_tau_deg)
        fpga.set_whole_angle(True, self.verify_rate_dps)
        fpga.set_agc(True, self.amplitude)
        fpga.set_drive_enabled(True)
        self._hold_amplitude(ctx)
        ctx.sleep(self._settle_s(ctx, "the precession starts", self.verify_rate_dps))
        off = self._record(ctx, VERIFY_OFF, self.verify_s, "drift, compensation off")
        ctx.log.info(recorded_text("drift, compensation off", TAP.column(off, "t_s"), self._spans[VERIFY_OFF]))
        fpga.set_drift_compensation(True, fit.delta_inv_tau_per_s, fit.theta_tau_deg)
        ctx.sleep(self._settle_s(ctx, "the compensation is on"))
        on = self._record(ctx, VERIFY_ON, self.verify_s, "drift, compensation on")
        ctx.log.info(recorded_text("drift, compensation on", TAP.column(on, "t_s"), self._spans[VERIFY_ON]))
        fpga.set_drift_compensation(False, fit.delta_inv_tau_per_s, fit.theta_tau_deg)
        fpga.set_drive_enabled(False)
        results, curves = self._verify_results(off, on, fit)
        for name, (th, rate) in curves.items():
            ctx.fit(f"hrg-damping drift {name}", theta_deg=np.degrees(th), drift_dph=rate)
        for res in results:
            ctx.report(res)

    def _settle_s(self, ctx, why: str, precession_dps: float = 0.0) -> float:
        """verify_settle_s, or (0) the loops' settle time after this command (settle_time_s); logged."""
        if self.verify_settle_s > 0:
            return self.verify_settle_s
        settle = settle_time_s(ctx.devices.fpga, precession_dps)
        ctx.log.info(f"settling {settle:.3g} s after {why} (loops' bandwidth"
                     + (f", the wave's turn of {SPLIT_LEARN_DEG:g} deg at {precession_dps:g} deg/s)" if precession_dps
                        else ")"))
        return settle

    # --- results, shared by the run and by `analysis` -----------------------------------------
    def _f0_hz(self, ctx) -> float:
        return float(ctx.devices.fpga.read_register("PLL_FREQ_HZ"))

    def _decay_results(self, fit, f0_hz: float | None) -> list[Result]:
        ci = fit.ci95
        out = [
            Result("theta_tau_deg", fit.theta_tau_deg, ci95=ci["theta_tau_deg"]),
            Result("delta_inv_tau_per_s", fit.delta_inv_tau_per_s, ci95=ci["delta_inv_tau_per_s"]),
            Result("tau_s", fit.tau_s, ci95=ci["tau_s"]),
        ]
        if f0_hz:
            out.append(Result("q_factor", fit.q_factor(f0_hz), ci95=fit.q_factor_ci95(f0_hz)))
        lo, hi = ci["delta_inv_tau_per_s"]
        k = self.bryan_factor
        out.append(Result("drift_predicted_dph", fit.drift_amplitude_dph(k),
                          ci95=(math.degrees(lo / 4 / k) * 3600, math.degrees(hi / 4 / k) * 3600)))
        return out

    def _verify_results(self, off: np.ndarray, on: np.ndarray, decay_fit=None) -> tuple[list[Result], dict]:
        """The drift against the wave angle, compensation off (`before`) and on (`after`), output-referred:
        drift_<name>_dph is the 4 theta part alone (a fit of mean + 4 theta; drift_reduction_ratio is
        their ratio), drift_<name>_{mean,4theta,8theta,12theta}_dph the drift in full (one fit of the
        mean and the three harmonics) and drift_<name>_rest_rms_dph the rms of what that fit leaves
        (noise).  With the decay's fit, drift_after_4theta_expected_dph: the 4 theta term that the fit's
        own error leaves after compensation (rms of |b - b_fit| / 4K; interval 0 to its 95 % bound)."""
        k = self.bryan_factor
        to_dph = math.degrees(1.0 / k) * 3600
        results, curves, amps = [], {}, {}
        cmd = math.radians(self.verify_rate_dps)
        for name, rows in (("before", off), ("after", on)):
            t_s = TAP.column(rows, "t_s")
            th = orbit_elements(TAP.columns_of(rows, *_Q))["theta_rad"]
            # the drift read from the angle record itself (harmonics of theta in the angle model,
            # linear least squares): +-0.1 deg/h where 1 s block slopes gave +-1.5 (docs/damping_drift.md)
            four = fit_angle_harmonics(t_s, th, cmd, orders=(4,)).drift.scaled(to_dph).harmonics[4]
            amps[name] = four.amplitude
            results.append(Result(f"drift_{name}_dph", four.amplitude, ci95=four.ci95))
            angle_fit = fit_angle_harmonics(t_s, th, cmd, orders=DRIFT_ORDERS)
            full = angle_fit.drift.scaled(to_dph)
            results.append(Result(f"drift_{name}_mean_dph", full.mean, ci95=full.mean_ci95))
            for m, h in full.harmonics.items():
                results.append(Result(f"drift_{name}_{m}theta_dph", h.amplitude, ci95=h.ci95))
                results.append(Result(f"drift_{name}_{m}theta_phase_deg", math.degrees(h.phase_rad),
                                      ci95=tuple(math.degrees(x) for x in h.phase_ci95)))
            # the figure's points: block slopes (drift_block_s) of the same record; the rest is what
            # they keep beyond the angle fit's mean + 4, 8, 12 theta model (noise, other harmonics)
            mids, rate = block_drift(t_s, th, self.drift_block_s)
            drift = rate - cmd
            rest = (drift - angle_fit.drift_rad_s(mids)) * to_dph
            results.append(Result(f"drift_{name}_rest_rms_dph", float(np.sqrt(np.mean(rest ** 2)))))
            curves[name] = (mids, drift * to_dph)
        ratio = amps["before"] / amps["after"] if amps["after"] > 0 else math.inf
        results.append(Result("drift_reduction_ratio", ratio))
        if decay_fit is not None:
            cov_b = np.asarray(decay_fit.covariance, dtype=float)[2:4, 2:4]
            if np.all(np.isfinite(cov_b)):
                rms = math.sqrt(max(float(np.trace(cov_b)), 0.0)) / 4.0 * to_dph
                bound = math.sqrt(5.991 * max(float(np.linalg.eigvalsh(cov_b)[-1]), 0.0)) / 4.0 * to_dph
                results.append(Result("drift_after_4theta_expected_dph", rms, ci95=(0.0, bound)))
        return results, curves

    def analysis(self, data) -> list[Result]:
        """Re-fit a recorded run: the decay and verification windows of `damping_windows`.  A run
        that ended during the record (killed, aborted, disk full) has no window yet: the decay
        recorded so far is fitted, from the start of the record step to the last sample."""
        fpga = data.table("fpga")
        if WINDOWS in data:
            win = data.table(WINDOWS)
        else:
            t0, t1 = data.step_span("record")
            t1 = min(fpga["t_s"][-1], math.inf if t1 is None else t1)
            if t0 is None or t1 <= t0:
                raise ValueError(f"{data.path.name} holds no decay: the run ended before the record step "
                                 f"({data.incomplete or 'no damping_windows stream'})")
            win = {"kind": np.array([DECAY]), "t_start_s": np.array([t0]), "t_end_s": np.array([t1])}
            data.notes.append(f"no {WINDOWS} stream: the decay fitted is the {t1 - t0:.1f} s recorded from the "
                              f"start of the record step (t = {t0:.1f} s) on, of the {self.record_s:g} s asked")
        rows = np.column_stack([fpga[c] for c in _TAP])
        period = float(np.median(np.diff(fpga["t_s"]) / np.maximum(np.diff(fpga["index"]), 1)))

        pauses = data.pauses() if hasattr(data, "pauses") else []
        sat = fpga.get("sat_flags")  # absent in raw files of protocol 2

        def window(kind: float) -> np.ndarray | None:
            sel = win["kind"] == kind
            if not sel.any():
                return None
            t0, t1 = win["t_start_s"][sel][-1], win["t_end_s"][sel][-1]
            t_s = TAP.column(rows, "t_s")
            inside = (t_s > t0) & (t_s <= t1)  # as the live tap: after t0, up to t1
            label = {DECAY: "free decay", VERIFY_OFF: "drift, compensation off",
                                        VERIFY_ON: "drift, compensation on"}[kind]
            if sat is not None and np.any(sat[inside] != 0):
                hit = inside & (sat != 0)
                raise ValueError(saturation_refusal(label, int(hit.sum()), int(np.bitwise_or.reduce(
                    sat[hit].astype(np.int64))), float(t_s[hit][0]), float(t_s[hit][-1])))
            paused = inside & in_spans(t_s, pauses)
            if paused.any():  # the live run excluded them too (pause_in_record): said, never silent
                data.notes.append(f"{label}: {int(paused.sum())} samples inside a pause left out of the fit")
            return rows[inside & ~paused]

        decay = self._decimate(window(DECAY), period)
        fit = fit_free_decay(*_decay_columns(decay), method=self.fit_method, model=self.fit_model)
        f0_hz = float(data.table(REF)["f0_hz"][-1]) if REF in data else None
        if f0_hz is None:
            data.notes.append(f"no {REF} stream: the reference frequency is unknown, so is q_factor")
        out = self._decay_results(fit, f0_hz)
        off, on = window(VERIFY_OFF), window(VERIFY_ON)
        if off is not None and on is not None:
            out += self._verify_results(off, on, fit)[0]
        elif self.compensate:
            data.notes.append("no verification windows: the drift before and after compensation was not measured")
        return out

    def figures(self, data) -> list:
        """The figures this run's results need (procedures.figures.hrg_damping): the report and
        `gyrobench analyze --figures` draw these."""
        from procedures.figures.hrg_damping import figures

        return figures(self, data)

    def figure_parts(self) -> list:
        """The same figures as independent parts (functions of the run's data) that a report may
        build and draw in parallel processes."""
        from procedures.figures.hrg_damping import figure_parts

        return figure_parts(self)
