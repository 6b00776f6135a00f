"""CVG noise terms from an Allan deviation (IEEE Std 952 annex C; issue 19): a static record of
hours in whole-angle mode, the rate output from the wave angle, the overlapping Allan deviation
(allantools) and the angle random walk, bias instability and rate random walk read off it with
their chi-squared intervals (bench.analysis.allan; docs/noise_model.md).

Steps: start the loops in whole-angle mode (no precession command) and hold the amplitude; let
the loops settle; record the FPGA stream at `stream_hz`; compute the rate, the Allan deviation and
the read-offs.  The record's window and the curve are recorded as declared streams, so
`analysis(data)` re-computes a recorded run with the same code.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from bench.analysis.allan import NoiseTerms, adev_band, allan_deviation, read_noise_terms
from bench.engine import Measurement, Param, Procedure, Result, recorded_text, step
from bench.streams import Column, StreamSchema, declare

from .hrg_damping import _StreamTap
from .hrg_excitation import HrgExcitation

WINDOW = "cvg_allan_window"
WINDOW_COLUMNS = declare(StreamSchema(WINDOW, "cvg-allan", (
    Column("t_start_s", "s", doc="start of the static record"), Column("t_end_s", "s", doc="its end"),
    Column("stream_hz", "Hz", doc="rate of the samples analysed"),
    Column("output_mode", "1", doc="the FPGA's output mode: 0 whole-angle (angle_out_deg), 1 force-to-rebalance "
                                   "(rate_out_dps)"),
    Column("scale_factor", "1", doc="output per input rate: -K (wave angle) or G K (rate output)")))).names  # fmt: skip
CURVE = "cvg_allan_curve"
CURVE_COLUMNS = declare(StreamSchema(CURVE, "cvg-allan", (
    Column("tau_s", "s", doc="cluster time"), Column("adev_dph", "deg/h", doc="overlapping Allan deviation"),
    Column("adev_low_dph", "deg/h", doc="lower end of its chi-squared interval"),
    Column("adev_high_dph", "deg/h", doc="upper end"),
    Column("clusters", "1", doc="overlapping differences averaged")))).names  # fmt: skip


def _truth_or_zero(key: str):
    """The simulator's value of a noise term; a station without that noise has none of it (0)."""
    return lambda truth: truth.get(key, 0.0)


def rate_from_stream(t_s: np.ndarray, angle_out_deg: np.ndarray, bryan_factor: float) -> tuple[np.ndarray, np.ndarray]:
    """The gyro's rate output in whole-angle mode (deg/h) between stream samples: the FPGA's
    wave-angle output's derivative divided by -K (the wave lags the case), at the midpoints."""
    rate_dps = -np.diff(np.asarray(angle_out_deg, dtype=float)) / np.diff(t_s) / bryan_factor
    return 0.5 * (t_s[1:] + t_s[:-1]), rate_dps * 3600.0


def rate_from_ftr(t_s: np.ndarray, rate_out_dps: np.ndarray, scale_factor: float) -> tuple[np.ndarray, np.ndarray]:
    """The gyro's rate (deg/h) in force-to-rebalance: the FPGA's rate output divided by its scale
    factor G K (docs/fpga_link.md, "Output modes"), at the frames' times."""
    return np.asarray(t_s, dtype=float), np.asarray(rate_out_dps, dtype=float) * 3600.0 / scale_factor


class CvgAllan(HrgExcitation, Procedure):
    """CVG noise terms: angle random walk, bias instability and rate random walk from an Allan deviation."""

    name = "cvg-allan"
    requires = ("fpga",)
    kinds = ("hrg",)

    record_s = Param(14400.0, unit="s", low=60.0, high=1e6, doc="static record (hours of it for the rate random walk)")
    settle_s = Param(30.0, unit="s", low=0.0, high=3600.0, doc="loops settling in whole-angle mode before the record")
    stream_hz = Param(10.0, unit="Hz", low=0.01, high=1000.0, doc="rate of the samples analysed (boxcar stream)")
    bryan_factor = Param(0.0, unit="", low=0.0, high=1.0,
                         doc="K: the rate output is the wave's rate / -K (0: the station's nominal K)")
    nominal_params = {"bryan_factor": "bryan_factor"}
    ftr_min_tau_s = Param(1.6, unit="s", low=0.0, high=3600.0,
                          doc="force-to-rebalance: the shortest tau read (the rebalance loop shapes the rate below ~3 "
                              "of its time constants, 0.5 s at FTR_KP = FTR_KI = 4; docs/noise_model.md)")
    confidence = Param(0.95, unit="", low=0.5, high=0.999, doc="level of the read-offs' intervals")

    pause_in_record = "restart"  # the Allan deviation takes one continuous record
    measurements = (
        Measurement("arw_deg_rth", "deg/sqrt(h)", "angle random walk N: sigma = N / sqrt(tau), the -1/2 slope "
                    "line's value at tau = 1 h (60 N deg/h at tau = 1 s), input-referred (the rebalance loop's "
                    "pickoff-noise term, docs/noise_model.md, adds 0.3 % in quadrature)",
                    truth=_truth_or_zero("arw_deg_rth")),
        Measurement("bias_instability_dph", "deg/h", "bias instability B: the flat minimum of the Allan "
                    "deviation / 0.664, the other terms' part removed", truth=_truth_or_zero("bias_instability_dph")),
        Measurement("rrw_dph_rth", "deg/h/sqrt(h)", "rate random walk K: sigma = K sqrt(tau / 3), the +1/2 "
                    "slope line's value at tau = 3 h",
                    truth=_truth_or_zero("rrw_dph_rth")),
        Measurement("allan_min_dph", "deg/h", "smallest Allan deviation of the curve (before any term is removed)"),
        Measurement("allan_min_tau_s", "s", "cluster time of the smallest Allan deviation",
                    no_interval="one of the octave-spaced cluster times, read off the curve: no interval"),
        Measurement("rate_mean_dph", "deg/h", "mean rate output over the record (bias + Earth's rate + drift)"),
    )

    def __init__(self, params: dict[str, Any] | None = None) -> None:
        super().__init__(params)
        self._tap = _StreamTap(("t_s", "angle_out_deg", "rate_out_dps"))
        self._rows: np.ndarray | None = None

    def demands(self) -> list:
        return []

    @step("Read the output mode, excite and hold the amplitude")
    def excite(self, ctx):
        fpga = ctx.devices.fpga
        self._mode = fpga.output_mode()
        if self._mode not in ("whole-angle", "force-to-rebalance"):
            raise RuntimeError(f"FPGA output mode {self._mode!r} is neither whole-angle nor force-to-rebalance")
        self._ftr = self._mode == "force-to-rebalance"
        k = self.bryan_factor
        self._scale = float(fpga.read_register("FTR_GAIN")) * k if self._ftr else -k
        ctx.subscribe(fpga, self._tap)
        ctx.subscribe(fpga, self._keep_latest)
        ctx.defer(self._tap.stop)
        self._start_loops(ctx)
        fpga.set_whole_angle(True, 0.0)
        a = self._hold_amplitude(ctx)
        ctx.log.info(f"amplitude {a:.4f} held (setpoint {self.amplitude:g}), {self._mode}, "
                     f"scale factor {self._scale:g}, no precession command")

    @step("Let the loops settle")
    def settle(self, ctx):
        ctx.sleep(self.settle_s)

    @step("Static record")
    def record(self, ctx):
        fpga = ctx.devices.fpga
        period = float(fpga.read_register("SAMPLE_PERIOD_S"))
        dec = max(1, int(round(1.0 / (self.stream_hz * period))))
        fpga.start_stream(dec)
        fpga.sync()
        self._tap.take(-math.inf, -math.inf)
        self._tap.on = True
        # to an absolute deadline; a pause inside restarts the record (pause_in_record)
        span = ctx.record_for(self.record_s, "static record", progress_every_s=60.0)
        fpga.sync()
        self._tap.on = False
        t0, t1 = span.t_start_s, span.t_end_s
        self._refuse_saturation(t0, t1, "static record")
        stream_hz = 1.0 / (dec * period)
        ctx.record(WINDOW, WINDOW_COLUMNS, np.array([[t0, t1, stream_hz, float(self._ftr), self._scale]]))
        self._rows = self._tap.take(t0, t1)
        self._stream_hz = stream_hz
        ctx.log.info(recorded_text("static record", self._rows[:, 0], span))

    @step("Allan deviation and noise terms")
    def allan(self, ctx):
        results, curve = ctx.compute(_analyse, self._rows, self._stream_hz, self._ftr, self._scale, self.confidence,
                                     self.ftr_min_tau_s)
        ctx.record(CURVE, CURVE_COLUMNS, curve)
        for res in results:
            ctx.report(res)

    # --- results, shared by the run and by `analysis` -----------------------------------------
    def analysis(self, data) -> list[Result]:
        """Re-compute a recorded run from its FPGA stream inside the record's window."""
        if WINDOW not in data:
            raise ValueError(f"{data.path.name} holds no static record ({data.incomplete or 'no ' + WINDOW})")
        win = data.table(WINDOW)
        t0, t1, hz = win["t_start_s"][-1], win["t_end_s"][-1], win["stream_hz"][-1]
        ftr = bool(win["output_mode"][-1]) if "output_mode" in win else False
        scale = float(win["scale_factor"][-1]) if "scale_factor" in win else -self.bryan_factor
        fpga = data.table("fpga")
        rows = np.column_stack([fpga[c] for c in ("t_s", "angle_out_deg", "rate_out_dps")])
        rows = rows[(rows[:, 0] > t0) & (rows[:, 0] <= t1)]
        return _analyse(rows, float(hz), ftr, scale, self.confidence, self.ftr_min_tau_s)[0]

    def figures(self, data) -> list:
        """The log-log Allan deviation with its band, the read-offs and the slope lines."""
        from procedures.figures.cvg_allan import figures

        return figures(self, data)


def _analyse(rows: np.ndarray, stream_hz: float, ftr: bool, scale_factor: float,
             level: float, ftr_min_tau_s: float = 0.0) -> tuple[list[Result], np.ndarray]:
    """Rate, Allan deviation, read-offs: (results, the curve's rows for CURVE).  rows: t_s,
    angle_out_deg, rate_out_dps; the rate from the rate output in force-to-rebalance (a frame
    carries the loop's last rate, not a boxcar mean; the read-offs from ftr_min_tau_s on, where the
    loop passes the rate unshaped), else from the wave angle (boxcar means)."""
    if rows is None or len(rows) < 16:
        n = 0 if rows is None else len(rows)
        raise RuntimeError(f"the static record holds {n} samples; at least 16 are needed")
    if ftr:
        _t, rate = rate_from_ftr(rows[:, 0], rows[:, 2], scale_factor)
    else:
        _t, rate = rate_from_stream(rows[:, 0], rows[:, 1], -scale_factor)
    curve = allan_deviation(rate, stream_hz)
    min_cluster = max(8, int(math.ceil(ftr_min_tau_s * stream_hz - 1e-9))) if ftr else 8
    terms = read_noise_terms(curve, level=level, boxcar=not ftr, min_cluster=min_cluster)
    lo, hi = adev_band(curve, terms)
    i_min = int(np.argmin(curve.adev))
    results = _term_results(terms) + [
        Result("allan_min_dph", float(curve.adev[i_min]), ci95=(float(lo[i_min]), float(hi[i_min]))),
        Result("allan_min_tau_s", float(curve.tau_s[i_min])),
        Result("rate_mean_dph", float(np.mean(rate)),
               ci95=_mean_interval(rate, terms, len(rate) / stream_hz)),
    ]
    table = np.column_stack([curve.tau_s, curve.adev, lo, hi, curve.n_clusters])
    return results, table


def _term_results(terms: NoiseTerms) -> list[Result]:
    return [Result(name, t.value, ci95=t.ci) for name, t in (
        ("arw_deg_rth", terms.arw), ("bias_instability_dph", terms.bias_instability), ("rrw_dph_rth", terms.rrw))]


def _mean_interval(rate: np.ndarray, terms: NoiseTerms, duration_s: float) -> tuple[float, float]:
    """The mean's 95 % interval from the Allan variance at the record's length (a rough one:
    sigma of a mean over T is about sigma_Allan(T))."""
    sd = float(terms.model_adev(np.array([duration_s]))[0])
    m = float(np.mean(rate))
    return (m - 1.96 * sd, m + 1.96 * sd)
