"""Rate-sensor (CVG) figures: the scale-factor series (output against rate with the fitted line,
residuals in ppm of full scale) and the static records of the bias test (input-referred rate per
batch, each turn-on's bias with its interval)."""

from __future__ import annotations

from typing import Any

import numpy as np

from bench.analysis.cvg_rate import level_means
from bench.figures import ReportFigure, new_figure


def scale_factor_figures(proc: Any, data: Any) -> list[ReportFigure]:
    """Output against the table rate with the least-squares line; the residuals in ppm of full scale."""
    if proc.windows_schema.name not in data or "fpga" not in data:
        return []
    fit = proc._analyse(data)
    fig, ax = new_figure(2, 1, height_in=4.6, sharex=True, gridspec_kw={"height_ratios": [3, 2]})
    top, bottom = ax[0, 0], ax[1, 0]
    order = np.argsort(fit.rate_dps, kind="stable")
    top.plot(fit.rate_dps, fit.output, "o", color="C0", markersize=3.5, label="window means")
    top.plot(fit.rate_dps[order], fit.fitted[order], "--", color="C3", linewidth=1.0,
             label=f"least squares: SF {fit.scale_factor:.7g}")
    top.set_ylabel("output (deg/s)")
    top.legend(loc="best")
    half = len(fit.rate_dps) // 2
    # the nonlinearity is the largest |mean of the up and down residuals at one rate|: those means
    # are the points drawn large; the single windows (rising, falling) faint beside them
    levels, level_ppm, _counts, _inv = level_means(fit.rate_dps, fit.residual_ppm)
    worst = int(np.argmax(np.abs(level_ppm)))
    bottom.plot(fit.rate_dps[:half], fit.residual_ppm[:half], "^", color="C0", markersize=3, alpha=0.45,
                label="rising (single window)")
    bottom.plot(fit.rate_dps[half:], fit.residual_ppm[half:], "v", color="C1", markersize=3, alpha=0.45,
                label="falling (single window)")
    bottom.plot(levels, level_ppm, "o-", color="k", markersize=4.5, label="up/down mean (nonlinearity)")
    bottom.plot([levels[worst]], [level_ppm[worst]], "o", markersize=9, markerfacecolor="none", color="C3",
                label=f"largest: {abs(level_ppm[worst]):.3g} ppm")
    bottom.axhline(0.0, color="C3", linewidth=0.8)
    bottom.set_ylabel("residual (ppm of FS)")
    bottom.set_xlabel("table rate Ω (deg/s)")
    bottom.legend(loc="best")
    note = (f"{len(fit.rate_dps)} windows; full scale {fit.full_scale_out:.4g} deg/s; nonlinearity (the largest "
            "|mean of the up and down residuals| at one rate: the black points, the largest ringed; the single "
            f"windows faint) {fit.nonlinearity_ppm:.3g} ppm "
            f"[{fit.nonlinearity_ppm_ci95[0]:.3g}, {fit.nonlinearity_ppm_ci95[1]:.3g}]; "
            f"asymmetry {fit.asymmetry_ppm:.3g} ppm; bias {fit.bias_dph:.3g} deg/h.")
    if fit.drift_terms is not None:
        note += (" Whole-angle: the drift with a 90-degree period in the wave's angle"
                 + (" and the read-out's distortion of the angle (a sin 4θ + b cos 4θ)"
                    if fit.distortion_terms is not None else "") + " are fitted beside the line.")
    return [ReportFigure("cvg_scale_factor", "Scale factor: output against rate, residuals", fig, note)]


def bias_figures(proc: Any, data: Any) -> list[ReportFigure]:
    """Each turn-on's batch rates (input-referred) and its bias with its 95 % interval."""
    if proc.windows_schema.name not in data or "fpga" not in data:
        return []
    est = proc._estimates(data)
    fig, ax = new_figure(1, 1, height_in=3.0)
    a = ax[0, 0]
    for i, e in enumerate(est):
        x = i + np.linspace(-0.3, 0.3, len(e.batch_dph))
        a.plot(x, e.batch_dph, ".", color="C0", markersize=3, label="batch rates" if i == 0 else None)
        a.errorbar([i], [e.bias_dph], yerr=[[e.bias_dph - e.ci95[0]], [e.ci95[1] - e.bias_dph]], fmt="s",
                   color="C3", markersize=4, capsize=3, label="bias, 95 %" if i == 0 else None)
    a.set_xticks(range(len(est)))
    a.set_xlabel("turn-on")
    a.set_ylabel("input-referred rate (deg/h)")
    a.legend(loc="best")
    return [ReportFigure("cvg_bias", "Bias at rest, turn-on by turn-on", fig,
                         f"{len(est)} turn-on(s); Earth's rate removed: {proc.earth_rate_on_axis_dph(data):.4g} deg/h"
                         + ("." if proc.earth_rate_dph else " (on the sensitive axis, from the station's latitude "
                            "and axis)."))]
