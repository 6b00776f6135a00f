"""cvg-bias: the drift series of IEEE Std 1431 at rest, in the station's output mode: the bias of
a static record with Earth's rate removed, and its repeatability over N turn-ons.

Steps: excite; then N times: a turn-on (the resonator quenched, the drive cut and switched on
again, the amplitude held), settle, record the output at rest.  Each record's bias
(bench.analysis.cvg_rate.static_bias: batch means of the rate output, or batch slopes of the wave
angle in whole-angle mode, divided by the scale factor) has a 95 % interval; the bias reported is
the mean over the turn-ons (Student's t on their scatter, so a turn-on spread widens it, never
narrower than the records' own noise allows), the
repeatability their spread with each record's own noise removed.  The scale factor that refers
the output to the input is the `scale_factor` parameter (from a cvg-scale-factor run), or the
mode's nominal one: G K in force-to-rebalance (the FPGA's FTR_GAIN register times the nominal
bryan_factor; 1 only where a lab trimmed G to 1/K), -bryan_factor in whole-angle.  A nominal 1 with
an untrimmed G left every bias (1 - G K) of itself low: -0.082 deg/h of 29.33 on sim-hrg-ftr
(G K = 0.9972), 3 sd over 20 seeds (benchmarks/truth_flags.py, issue 31 item 8).
"""

from __future__ import annotations

import numpy as np

from bench.analysis.cvg_rate import static_bias, turn_on_repeatability
from bench.engine import Demand, Measurement, Param, Procedure, Result, step
from bench.streams import Column, StreamSchema, declare

from .cvg_output import (
    MODES,
    TURN_ON_SIGMA_KEY,
    UNSTATED_BIAS_NO_TRUTH,
    CvgOutput,
    static_bias_truth,
    turn_on_sigma_truth,
)

WINDOWS = declare(StreamSchema("cvg_bias_windows", "cvg-bias", (
    Column("t_start_s", "s"), Column("t_end_s", "s"), Column("turn_on", "1", "i8"),
    Column("mode", "1", "i8", legend={0: "whole-angle", 1: "force-to-rebalance"}),
    Column("scale_factor", "1", doc="scale factor the output was referred to the input with"),
)))


#: why the first turn-on's bias may be compared with no truth
FIRST_TURN_ON_NO_TRUTH = ("no truth when the unit's turn-on bias varies from one turn-on to the next (the "
                          "simulator's truth keeps the mean and the last draw, not this record's), or "
                          + UNSTATED_BIAS_NO_TRUTH.removeprefix("no truth "))


def first_turn_on_bias_truth(truth: dict[str, float]) -> float | None:
    """The first turn-on's bias: the static bias where every turn-on has the same one; None where
    it varies (its record's own interval cannot hold the turn-on's spread: 20 of 20 seeds outside)."""
    if truth.get(TURN_ON_SIGMA_KEY, 0.0) > 0.0:
        return None
    return static_bias_truth(truth)


class CvgBias(CvgOutput, Procedure):
    """Bias at rest (Earth's rate removed) and its turn-on to turn-on repeatability."""

    name = "cvg-bias"
    #: the turn-on windows' stream (its figures read it here)
    windows_schema = WINDOWS
    requires = ("fpga",)
    kinds = ("hrg",)

    record_s = Param(60.0, unit="s", low=1.0, high=1e6, doc="static record after each turn-on")
    turn_ons = Param(3, low=1, high=100, doc="turn-ons (each followed by a static record)")
    quench_s = Param(10.0, unit="s", low=0.0, high=3600.0,
                     doc="time the AGC pulls the amplitude to zero before a turn-on")
    batches = Param(10, low=2, high=1000, doc="batches of each record for its bias interval")
    scale_factor = Param(0.0, low=-1e6, high=1e6,
                         doc="output per input rate (from cvg-scale-factor); 0: the mode's nominal one "
                             "(force-to-rebalance: the FPGA's FTR_GAIN x bryan_factor; whole-angle: -bryan_factor)")
    settle_s = Param(30.0, unit="s", low=0.0, high=3600.0,
                     doc="warm-up after a turn-on holds the amplitude (the quadrature settles over tens of s)")
    bryan_factor = Param(0.0, low=0.0, high=1.0,
                         doc="nominal K: whole-angle's nominal scale factor is -K (0: the station's nominal K)")
    nominal_params = {"bryan_factor": "bryan_factor"}

    measurements = (
        Measurement("bias_dph", "deg/h", "bias at rest, Earth's rate removed: mean over the turn-ons",
                    truth=static_bias_truth,
                    no_truth=UNSTATED_BIAS_NO_TRUTH),
        Measurement("bias_first_dph", "deg/h", "bias of the first turn-on's record", truth=first_turn_on_bias_truth,
                    no_truth=FIRST_TURN_ON_NO_TRUTH),
        Measurement("bias_repeatability_dph", "deg/h", "turn-on to turn-on spread of the bias (1 sigma), "
                    "each record's own noise removed", truth=turn_on_sigma_truth,
                    when=lambda p: p.turn_ons >= 2, when_doc="turn_ons >= 2"),
        Measurement("bias_record_sigma_dph", "deg/h", "standard error of one record's bias (rms over the turn-ons)"),
    )

    def demands(self) -> list[Demand]:
        return []

    @step("Excite and hold the amplitude")
    def excite(self, ctx):
        ctx.subscribe(ctx.devices.fpga, self._keep_latest)
        self._start_output(ctx)
        self._start_loops(ctx)
        self._hold_amplitude(ctx)

    @step("Turn-ons and static records")
    def records(self, ctx):
        code = MODES.index(self._mode)
        sf = self._scale_factor(ctx)
        for i in range(self.turn_ons):
            self._turn_on(ctx, self.quench_s)
            ctx.sleep(self.settle_s)
            t0, t1 = self._record_window(ctx, self.record_s, f"turn-on {i + 1} record")
            ctx.record(WINDOWS, WINDOWS.names, np.array([[t0, t1, i, code, sf]]))
            ctx.progress((i + 1) / self.turn_ons, f"turn-on {i + 1} / {self.turn_ons}")

    @step("Bias and repeatability")
    def estimate(self, ctx):
        for res in self.analysis(ctx.data()):
            ctx.report(res)

    # --- analysis --------------------------------------------------------------------------
    def _estimates(self, data):
        win = data.table(WINDOWS.name)
        fpga = data.table("fpga")
        t = fpga["t_s"]
        earth_dph = self.earth_rate_on_axis_dph(data)
        out = []
        for t0, t1, mode, sf in zip(win["t_start_s"], win["t_end_s"], win["mode"], win["scale_factor"], strict=True):
            sel = (t > t0) & (t <= t1)
            name = MODES[int(mode)]
            y = fpga["rate_out_dps"][sel] if name == "force-to-rebalance" else fpga["angle_out_deg"][sel]
            out.append(static_bias(t[sel], y, mode=name, scale_factor=float(sf), earth_rate_dph=earth_dph,
                                   n_batches=self.batches))
        return out

    def analysis(self, data) -> list[Result]:
        """Bias and repeatability from a recorded run's `cvg_bias_windows` and `fpga` streams."""
        est = self._estimates(data)
        if not est:
            raise RuntimeError("no static record in this run")
        first = est[0]
        out = [Result("bias_first_dph", first.bias_dph, ci95=first.ci95)]
        sig = np.array([e.sigma_dph for e in est])
        out.append(Result("bias_record_sigma_dph", float(np.sqrt(np.mean(sig**2)))))
        if len(est) >= 2:
            rep = turn_on_repeatability(np.array([e.bias_dph for e in est]), sig)
            out.append(Result("bias_dph", rep.mean_dph, ci95=rep.mean_ci95))
            out.append(Result("bias_repeatability_dph", rep.sigma_dph, ci95=rep.ci95))
        else:
            out.append(Result("bias_dph", first.bias_dph, ci95=first.ci95))
        return out

    def figures(self, data) -> list:
        """Each turn-on's input-referred rate (batch means) with its bias and interval."""
        from procedures.figures.cvg import bias_figures

        return bias_figures(self, data)
