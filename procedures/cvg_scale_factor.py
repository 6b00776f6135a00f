"""cvg-scale-factor: the scale-factor series of IEEE Std 1431 on a rate table, in the station's
output mode (force-to-rebalance or whole-angle).

Steps: excite and hold the amplitude (whole-angle: then precess the wave a quarter turn, so the
FPGA has learnt the split's pattern before the first window); then for each table rate of a
series from -R to +R and back (both directions) set the rate, wait until it is stable, settle,
and average the output over a window (by default whole turns of the table, so its
angle-dependent ripple averages out); fit
by generalised least squares (bench.analysis.cvg_rate.fit_scale_factor; the windows' errors a
bias wandering from the turn-on, as rate random walk and flicker make it): the scale factor, the
bias (input-referred, Earth's rate removed), the nonlinearity in ppm of full scale and the
asymmetry of the positive and negative rates' scale factors, each with a 95 % interval.  In
whole-angle mode the output of a window is the slope of the wave angle; the damping drift that
turns with the wave and the read-out's distortion of the angle (unequal pickoff gains: the read
angle is off by a sin 4 theta + b cos 4 theta, a rate-proportional error that whole table turns
do not average out, +26 ppm of K on sim-hrg-wa before it was fitted) are fitted beside the line.  The windows go to
the `cvg_sf_windows` stream, so `analysis(data)` re-fits a recorded run with the same code.
"""

from __future__ import annotations

import math

import numpy as np

from bench.analysis.cvg_rate import fit_scale_factor
from bench.engine import Demand, Measurement, Param, Procedure, Result, StationMismatch, step
from bench.streams import Column, StreamSchema, declare

from .cvg_output import MODES, UNSTATED_BIAS_NO_TRUTH, CvgOutput, mean_bias_truth, scale_factor_truth, window_outputs

WINDOWS = declare(StreamSchema("cvg_sf_windows", "cvg-scale-factor", (
    Column("t_start_s", "s"), Column("t_end_s", "s"), Column("rate_dps", "deg/s", doc="table rate commanded"),
    Column("mode", "1", "i8", legend={0: "whole-angle", 1: "force-to-rebalance"}),
    Column("box_s", "s", doc="whole-angle: the boxes at the window's ends whose mean angles give its rate (0: slope)"),
)))


#: whole-angle fit: bias, scale factor, the drift's and the distortion's cos / sin 4 theta terms
WHOLE_ANGLE_UNKNOWNS = 6


def rate_series(max_rate_dps: float, steps: int) -> np.ndarray:
    """-R .. +R in 2 steps + 1 equal levels, then back from +R to -R (both directions)."""
    up = np.linspace(-max_rate_dps, max_rate_dps, 2 * steps + 1)
    return np.concatenate([up, up[::-1]])


def window_s(rate_dps: float, average_s: float, whole_turns: bool) -> tuple[float, float]:
    """The averaging window at a rate and the boxes at its ends (whole-angle reads the rate off the
    change of the angle's mean from the first box to the last): average_s and no boxes, or with
    whole_turns the shortest whole number of table turns at least average_s long plus one box
    (1 s, at most a quarter turn), so the boxes lie whole turns apart.  The table's angle-dependent
    rate ripple integrates to zero over a turn; over part of one it biases the window's mean by up
    to ripple x rate / window, which scales with the rate like a scale factor error."""
    if not whole_turns or rate_dps == 0.0:
        return average_s, 0.0
    turn_s = 360.0 / abs(rate_dps)
    box_s = min(1.0, 0.25 * turn_s)
    return turn_s * max(1, math.ceil(average_s / turn_s - 1e-9)) + box_s, box_s


class CvgScaleFactor(CvgOutput, Procedure):
    """Scale factor, bias, nonlinearity and asymmetry from a rate series in both directions."""

    name = "cvg-scale-factor"
    #: the rate windows' stream (its figures read it here)
    windows_schema = WINDOWS
    requires = ("table", "fpga")
    kinds = ("hrg",)

    max_rate_dps = Param(20.0, unit="deg/s", low=0.01, high=1000.0, doc="full-scale rate R of the series")
    steps = Param(4, low=1, high=50, doc="rate levels on each side of zero (2 steps + 1 levels, up then down)")
    average_s = Param(10.0, unit="s", low=0.1, high=3600.0, doc="averaging window at each rate (at least)")
    whole_turns = Param(True, doc="lengthen each window to whole turns of the table (its angle ripple then averages "
                                  "out of the rate)")
    accel_dps2 = Param(100.0, unit="deg/s^2", low=0.1, high=10000.0, doc="table acceleration")
    learn_split_deg = Param(90.0, unit="deg", low=0.0, high=720.0,
                            doc="whole-angle: precess the wave this far before the first window, so the "
                                "FPGA's quadrature loop has seen the split's whole 4-theta pattern (0: no)")
    learn_settle_s = Param(10.0, unit="s", low=0.0, high=600.0,
                           doc="whole-angle: wait after that precession (the quadrature loop's integrator settles)")

    measurements = (
        Measurement("scale_factor", "", "least-squares scale factor: output per input rate (deg/s per deg/s; "
                    "whole-angle: wave-angle rate per input rate, -K)", truth=scale_factor_truth),
        Measurement("bias_dph", "deg/h", "input-referred bias of this turn-on, Earth's rate removed (whole-angle: "
                    "the mean over the wave's angle)", truth=mean_bias_truth,
                    no_truth=UNSTATED_BIAS_NO_TRUTH),
        Measurement("nonlinearity_ppm", "ppm", "largest residual of the line in ppm of full-scale output",
                    truth=lambda t: 0.0),
        Measurement("asymmetry_ppm", "ppm", "positive minus negative rates' scale factor over their mean, ppm",
                    truth=lambda t: 0.0),
        Measurement("residual_sigma_ppm", "ppm", "scatter of one point about the line, ppm of full scale",
                    no_interval="a statistic of this record, not an estimate of a parameter: no interval"),
    )

    def demands(self) -> list[Demand]:
        return [
            Demand("table", "max_rate_dps", "max_rate_dps", self.max_rate_dps, "deg/s"),
            Demand("table", "max_accel_dps2", "accel_dps2", self.accel_dps2, "deg/s^2"),
        ]

    def preflight(self, devices) -> None:
        """Whole-angle fits six unknowns (bias, scale factor, the damping drift's and the read-out
        distortion's cos/sin 4 theta terms) and needs a window more to see their scatter (read-only)."""
        fpga = devices.get("fpga") if hasattr(devices, "get") else None
        if fpga is None or fpga.output_mode() != "whole-angle":
            return
        windows = len(rate_series(self.max_rate_dps, self.steps))
        if windows <= WHOLE_ANGLE_UNKNOWNS:
            raise StationMismatch(
                f"{self.name}: steps={self.steps} gives {windows} rate windows; in whole-angle mode the fit has "
                f"{WHOLE_ANGLE_UNKNOWNS} unknowns and needs at least {WHOLE_ANGLE_UNKNOWNS + 1} windows "
                f"(steps >= 2); nothing was moved")

    @step("Excite and hold the amplitude")
    def excite(self, ctx):
        ctx.subscribe(ctx.devices.fpga, self._keep_latest)
        self._start_output(ctx)
        self._start_loops(ctx)
        self._hold_amplitude(ctx)
        self._learn_split(ctx, self.learn_split_deg, self.learn_settle_s)
        ctx.devices.table.enable()

    @step("Rate series")
    def series(self, ctx):
        rates = rate_series(self.max_rate_dps, self.steps)
        table = ctx.devices.table
        code = MODES.index(self._mode)
        for i, rate in enumerate(rates):
            table.set_rate(float(rate), self.accel_dps2)
            table.wait_at_rate(self.rate_tolerance_dps, self.rate_hold_s, self.rate_timeout_s)
            ctx.sleep(self._settle_s(ctx))
            length_s, box_s = window_s(float(rate), self.average_s, self.whole_turns)
            t0, t1 = self._record_window(ctx, length_s, f"window at {rate:+.6g} deg/s")
            ctx.record(WINDOWS, WINDOWS.names, np.array([[t0, t1, rate, code, box_s]]))
            ctx.progress((i + 1) / len(rates), f"rate {i + 1} / {len(rates)}: {rate:+.3g} deg/s")
        table.set_rate(0.0, self.accel_dps2)

    @step("Fit")
    def fit(self, ctx):
        fit = self._analyse(ctx.data())
        for res in self._results(fit):
            ctx.report(res)
        ctx.fit("cvg-scale-factor line", rate_dps=fit.rate_dps, output=fit.output, fitted=fit.fitted)
        ctx.log.info(f"scale factor {fit.scale_factor:.7g}, bias {fit.bias_dph:.3g} deg/h, "
                     f"nonlinearity {fit.nonlinearity_ppm:.3g} ppm, asymmetry {fit.asymmetry_ppm:.3g} ppm")

    # --- analysis --------------------------------------------------------------------------
    def _analyse(self, data):
        win = data.table(WINDOWS.name)
        mode = MODES[int(win["mode"][-1])]
        out = window_outputs(data, win, mode)
        wa = mode == "whole-angle"
        # the bias wanders from the turn-on (the drive comes on in the first step, at the record's start)
        t_mid = 0.5 * (win["t_start_s"] + win["t_end_s"]) - float(data.table("fpga")["t_s"][0])
        return fit_scale_factor(win["rate_dps"], out[:, 0], drift_basis=out[:, 1:3] if wa else None,
                                distortion_basis=out[:, 3:5] if wa else None, t_mid_s=t_mid,
                                earth_rate_dph=self.earth_rate_on_axis_dph(data))

    @staticmethod
    def _results(fit) -> list[Result]:
        return [
            Result("scale_factor", fit.scale_factor, ci95=fit.scale_factor_ci95),
            Result("bias_dph", fit.bias_dph, ci95=fit.bias_dph_ci95),
            Result("nonlinearity_ppm", fit.nonlinearity_ppm, ci95=fit.nonlinearity_ppm_ci95),
            Result("asymmetry_ppm", fit.asymmetry_ppm, ci95=fit.asymmetry_ppm_ci95),
            Result("residual_sigma_ppm", fit.sigma_out / fit.full_scale_out * 1e6),
        ]

    def analysis(self, data) -> list[Result]:
        """Re-fit a recorded run from its `cvg_sf_windows` and `fpga` streams."""
        return self._results(self._analyse(data))

    def figures(self, data) -> list:
        """The output against the rate with the fitted line, and the residuals in ppm of full scale."""
        from procedures.figures.cvg import scale_factor_figures

        return scale_factor_figures(self, data)
