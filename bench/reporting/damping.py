"""hrg-damping figures: ln E with its fit and residuals, the wave angle and quadrature, the drift
against the wave angle before and after compensation with the fitted harmonics and residuals,
the table's rate and angle, and the FPGA's slow variables."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .figures import ReportFigure, fit_with_residuals, label, measurement, new_figure, stream_figure, table_figure
from .numbers import with_interval

HARMONICS = (4, 8, 12)


def harmonic_fit(theta_rad: np.ndarray, y: np.ndarray, harmonics: tuple[int, ...] = HARMONICS) -> dict[str, Any]:
    """Least squares of y = mean + sum_k (a_k cos k theta + b_k sin k theta): coefficients,
    amplitudes |a_k, b_k| with 95 % intervals (delta method, t quantile) and a model function."""
    from scipy import special

    th, y = np.asarray(theta_rad, dtype=float), np.asarray(y, dtype=float)

    def design(t: np.ndarray) -> np.ndarray:
        cols = [np.ones_like(t)]
        for k in harmonics:
            cols += [np.cos(k * t), np.sin(k * t)]
        return np.column_stack(cols)

    x = design(th)
    p, *_ = np.linalg.lstsq(x, y, rcond=None)
    r = y - x @ p
    dof = max(len(y) - len(p), 1)
    cov = float(r @ r) / dof * np.linalg.pinv(x.T @ x)
    tq = float(special.stdtrit(dof, 0.975))
    terms = {"mean": (float(p[0]), (float(p[0] - tq * math.sqrt(cov[0, 0])), float(p[0] + tq * math.sqrt(cov[0, 0]))))}
    for i, k in enumerate(harmonics):
        a, b = p[1 + 2 * i], p[2 + 2 * i]
        amp = math.hypot(a, b)
        g = np.zeros(len(p))
        if amp > 0:
            g[1 + 2 * i], g[2 + 2 * i] = a / amp, b / amp
        sd = math.sqrt(max(float(g @ cov @ g), 0.0))
        terms[f"{k}θ"] = (amp, (max(0.0, amp - tq * sd), amp + tq * sd))
    return {"p": p, "terms": terms, "model": lambda t: design(np.asarray(t, dtype=float)) @ p, "residual": r}


def energy_figure(data: Any) -> list[ReportFigure]:
    fits = data.fits()
    e = fits.get("hrg-damping energy")
    if not e:
        return []
    t, energy, efit = e["t_s"], e["energy"], e["energy_fit"]
    ok = (energy > 0) & (efit > 0)
    res = fits.get("hrg-damping residuals", {}).get("residual_ln_e")
    res = res[ok] if res is not None and len(res) == len(t) else None
    fig = fit_with_residuals(t[ok], np.log(energy[ok]), np.log(efit[ok]), xname="t_s", yname="ln E",
                             ylabel="ln E (E in model units²)", fit_label="free-decay fit", residual=res,
                             residual_label="residual ln E")
    tau = measurement(data, "tau_s")
    note = "Energy E = cx² + sx² + cy² + sy² of the decay record and the fitted free-decay model."
    if tau:
        v, ci = with_interval(tau["value"], tau.get("ci95"))
        note += f" τ = {v} s, 95 % interval {ci} s."
    return [ReportFigure("hrg-damping_energy", "Free decay: ln E with the fit and residuals", fig, note)]


def theta_figure(data: Any) -> list[ReportFigure]:
    fits = data.fits()
    th = fits.get("hrg-damping theta")
    if not th:
        return []
    quad = fits.get("hrg-damping quadrature")
    rows = 2 if quad else 1
    fig, ax = new_figure(rows, 1, height_in=1.4 + 1.3 * rows, sharex=True)
    ax[0, 0].plot(th["t_s"], th["theta_deg"], color="C0")
    ax[0, 0].set_ylabel(label("theta_deg"))
    if quad:
        ax[1, 0].plot(quad["t_s"], quad["quadrature_rel"], color="C2")
        ax[1, 0].set_ylabel(label("quadrature_rel"))
    ax[-1, 0].set_xlabel(label("t_s"))
    return [ReportFigure("hrg-damping_theta", "Free decay: wave angle θ(t) and quadrature", fig,
                         "Wave angle (unwrapped) and relative quadrature k/a during the decay record.")]


def drift_figure(data: Any) -> list[ReportFigure]:
    """Drift against the wave angle before and after compensation: points, the mean + 4θ model of
    drift_before/after_dph and the mean + 4θ, 8θ, 12θ harmonics fitted here, residuals beneath."""
    fits = data.fits()
    curves = {n: fits.get(f"hrg-damping drift {n}") for n in ("before", "after")}
    curves = {n: c for n, c in curves.items() if c and len(c.get("theta_deg", ())) >= 8}
    if not curves:
        return []
    fig, ax = new_figure(2, len(curves), height_in=3.8, sharex=True, sharey="row",
                         gridspec_kw={"height_ratios": [3, 1.3]})
    rows = []
    grid = np.linspace(-45.0, 45.0, 361)
    for j, (name, c) in enumerate(curves.items()):
        # the harmonics repeat every 90 deg: the unwrapped angle folded into [-45, 45)
        th, y = (np.asarray(c["theta_deg"]) + 45.0) % 90.0 - 45.0, np.asarray(c["drift_dph"])
        full = harmonic_fit(np.radians(th), y)
        four = harmonic_fit(np.radians(th), y, (4,))
        top, bottom = ax[0, j], ax[1, j]
        top.plot(th, y, ".", color="C0", markersize=3, label="measured (per block)")
        top.plot(grid, four["model"](np.radians(grid)), "--", color="C1", label="mean + 4θ")
        top.plot(grid, full["model"](np.radians(grid)), color="C3", label="mean + 4θ, 8θ, 12θ")
        top.set_title(f"compensation {'off' if name == 'before' else 'on'} ({name})")
        bottom.plot(th, full["residual"], ".", color="C0", markersize=3)
        bottom.axhline(0.0, color="C3", linewidth=0.8)
        bottom.set_xlabel(label("theta_deg"))
        if j == 0:
            top.set_ylabel(label("drift_dph"))
            bottom.set_ylabel("residual (deg/h)")
        for term, (v, ci) in full["terms"].items():
            rows.append([name, term, *with_interval(v, ci), "deg/h"])
        m = measurement(data, f"drift_{name}_dph")
        if m:
            rows.append([name, f"4θ alone: drift_{name}_dph (reported)", *with_interval(m["value"], m.get("ci95")),
                         "deg/h"])
    fig.legend(*ax[0, 0].get_legend_handles_labels(), loc="outside upper center", ncols=3)
    note = ("Drift rate per block against the wave angle (folded into one 90° period), referred to the gyro output "
            "(÷ K), with the residual of the mean + 4θ, 8θ, 12θ model beneath. The raw file holds the 4θ amplitude "
            "only, so the mean and the harmonics are fitted here for the figure; amplitudes with 95 % intervals below.")
    return [ReportFigure("hrg-damping_drift", "Drift against the wave angle, before and after compensation", fig,
                         note, (["record", "term", "amplitude", "95 % interval", "unit"], rows))]


def figures(proc: Any, data: Any) -> list[ReportFigure]:
    """Every figure an hrg-damping run's results need, in the report's order."""
    out = energy_figure(data) + theta_figure(data) + drift_figure(data) + table_figure(data)
    if "fpga" in data:
        fig = stream_figure(data, "fpga", ["cx", "sx", "cy", "sy"], title="FPGA stream: slow variables",
                            key="hrg-damping_fpga")
        if fig is not None:
            out.append(fig)
    return out
