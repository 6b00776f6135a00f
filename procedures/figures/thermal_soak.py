"""thermal-soak's report figures: the bias and the resonator frequency at each settled set point
against the case temperature, with the fitted polynomials and their residuals."""

from __future__ import annotations

from typing import Any

import numpy as np

from bench.figures import ReportFigure, new_figure


def temperature_figure(proc: Any, data: Any) -> list[ReportFigure]:
    """The chamber air and the case through the run, the settled records marked."""
    if "chamber" not in data:
        return []
    ch = data.table("chamber")
    fig, ax = new_figure(1, 1, height_in=3.0)
    a = ax[0, 0]
    a.plot(ch["t_s"] / 3600.0, ch["air_degc"], "-", color="C0", lw=1.0, label="chamber air")
    a.plot(ch["t_s"] / 3600.0, ch["part_degc"], "-", color="C3", lw=1.0, label="case (part thermocouple)")
    if proc.windows_schema.name in data:
        win = data.table(proc.windows_schema.name)
        for i, (t0, t1) in enumerate(zip(win["t_start_s"], win["t_end_s"], strict=True)):
            a.axvspan(t0 / 3600.0, t1 / 3600.0, color="0.8", label="settled records" if i == 0 else None)
    a.set_xlabel("bench time (h)")
    a.set_ylabel("temperature (degC)")
    a.legend(loc="best")
    return [ReportFigure("thermal-soak_temperatures", "Chamber and case temperatures", fig,
                         "Air ramps at the controller's limit; the case follows it; each record starts once "
                         "the resonator frequency has stopped drifting.")]


def fit_figures(proc: Any, data: Any) -> list[ReportFigure]:
    """Frequency and bias against temperature with their fits (top) and residuals (bottom)."""
    if proc.windows_schema.name not in data or "fpga" not in data:
        return []
    p, bias, f0 = proc.fits(data)
    t = p["part_c"]
    tt = np.linspace(t.min(), t.max(), 200)
    f25 = float(f0.coeffs[0])
    fig, ax = new_figure(2, 2, height_in=5.0)
    a = ax[0, 0]
    a.errorbar(t, p["f0_hz"] - f25, yerr=1.96 * p["f0_se_hz"], fmt="o", color="C0", markersize=4, capsize=3,
               label="settled records, 95 %")
    a.plot(tt, f0(tt) - f25, "-", color="C3", label=f"order {f0.order} (BIC)")
    a.set_ylabel(f"f0 - {f25:.3f} Hz (Hz)")
    a.legend(loc="best")
    a = ax[1, 0]
    a.errorbar(t, 1e3 * f0.residuals, yerr=1.96e3 * p["f0_se_hz"], fmt="o", color="C0", markersize=4, capsize=3)
    a.axhline(0.0, color="0.5", lw=0.8)
    a.set_xlabel("case temperature (degC)")
    a.set_ylabel("f0 residual (mHz)")
    a = ax[0, 1]
    a.errorbar(t, p["bias_dph"], yerr=1.96 * p["bias_se_dph"], fmt="o", color="C0", markersize=4, capsize=3,
               label="settled records, 95 %")
    a.plot(tt, bias(tt), "-", color="C3", label=f"order {bias.order} (BIC)")
    a.set_ylabel("bias (deg/h)")
    a.legend(loc="best")
    a = ax[1, 1]
    a.errorbar(t, bias.residuals, yerr=1.96 * p["bias_se_dph"], fmt="o", color="C0", markersize=4, capsize=3)
    a.axhline(0.0, color="0.5", lw=0.8)
    a.set_xlabel("case temperature (degC)")
    a.set_ylabel("bias residual (deg/h)")
    return [ReportFigure("thermal-soak_fits", "Frequency and bias against temperature", fig,
                         f"{len(t)} set points; fits about 25 degC, order by BIC (docs/chamber.md).")]
