"""thermal-ramp's report figures: the temperatures through the cycle, the frequency against the
case thermocouple by branch (the resonator's lag as a loop), and the bias against each thermometer
with its fit and residuals, the verification records before and after the trim."""

from __future__ import annotations

from typing import Any

import numpy as np

from bench.figures import ReportFigure, new_figure


def temperature_figure(proc: Any, data: Any) -> list[ReportFigure]:
    """The chamber air and the case through the run."""
    if "chamber" not in data:
        return []
    ch = data.table("chamber")
    fig, ax = new_figure(1, 1, height_in=3.0)
    a = ax[0, 0]
    a.plot(ch["t_s"] / 60.0, ch["air_degc"], "-", color="C0", lw=1.0, label="chamber air")
    a.plot(ch["t_s"] / 60.0, ch["part_degc"], "-", color="C3", lw=1.0, label="case (part thermocouple)")
    a.set_xlabel("bench time (min)")
    a.set_ylabel("temperature (degC)")
    a.legend(loc="best")
    return [ReportFigure("thermal-ramp_temperatures", "Chamber and case temperatures", fig,
                         "The cycle's heating and cooling branches at the chamber's ramp, then the verification "
                         "set points.")]


def fit_figures(proc: Any, data: Any) -> list[ReportFigure]:
    """Frequency against the thermocouple by branch (left); bias against each thermometer with the
    chosen fits (right top), their residuals (right bottom), the verification before and after."""
    if proc.windows_schema.name not in data or "fpga" not in data:
        return []
    p, bias, f0, _ = proc.fits(data)
    heat = p["branch"] == 0
    f25 = float(f0.coeffs[0])
    fig, ax = new_figure(2, 2, height_in=5.0)
    a = ax[0, 0]
    for sel, name, c in ((heat, "heating", "C3"), (~heat, "cooling", "C0")):
        a.plot(p["part_c"][sel], p["f0_hz"][sel] - f25, "o-", color=c, markersize=3, lw=0.8, label=name)
    a.set_ylabel(f"f0 - {f25:.3f} Hz (Hz)")
    a.legend(loc="best")
    a = ax[1, 0]
    for sel, c in ((heat, "C3"), (~heat, "C0")):
        a.plot(p["part_c"][sel], 1e3 * f0.residuals[sel], "o", color=c, markersize=3)
    a.axhline(0.0, color="0.5", lw=0.8)
    a.set_xlabel("case thermocouple (degC)")
    a.set_ylabel("f0 residual (mHz)")
    a = ax[0, 1]
    t_f = p["frequency_c"]
    a.errorbar(t_f, p["bias_dph"], yerr=1.96 * p["bias_se_dph"], fmt="o", color="0.5", markersize=3, capsize=2,
               label="segments, 95 %")
    tt = np.linspace(t_f.min(), t_f.max(), 200)
    a.plot(tt, bias["frequency"](tt), "-", color="C3", label=f"order {bias['frequency'].order} (BIC)")
    if proc.verify_points and "thermal_ramp_verify" in data:
        v = proc.verification(data)
        raw = v["raw_bias_dph"]
        line = proc.trim_line(p)
        t_v = 25.0 + (v["f0_hz"] - f0(25.0)) / f0.slope_at(25.0)
        a.plot(t_v, raw, "s", color="C2", label="verification, untrimmed")
        a.plot(t_v, raw - line(v["f_offset_hz"]), "D", color="C1", label="verification, trimmed")
    a.set_ylabel("bias (deg/h)")
    a.legend(loc="best", fontsize="small")
    a = ax[1, 1]
    for k, c in (("air", "C0"), ("part", "C2"), ("frequency", "C3")):
        x = {"air": p["air_c"], "part": p["part_c"], "frequency": t_f}[k]
        rms = float(np.sqrt(np.mean(bias[k].residuals ** 2)))
        a.plot(x, bias[k].residuals, "o", color=c, markersize=3, label=f"vs {k}: {rms:.3g} rms")
    a.axhline(0.0, color="0.5", lw=0.8)
    a.set_xlabel("temperature (degC)")
    a.set_ylabel("bias residual (deg/h)")
    a.legend(loc="best", fontsize="small")
    return [ReportFigure("thermal-ramp_fits", "Frequency and bias against temperature", fig,
                         f"{len(t_f)} segments over both branches; the bias against the air, the case thermocouple "
                         "and the resonator frequency as a thermometer (docs/chamber.md).")]
