"""hrg-selfcal figures after the CETC paper's figures 3-7: identified X/Y gain difference against
time, damping anisotropy against time, drift against wave angle (measured and identified), the
integrated angle error against time and the mean bias since start."""

from __future__ import annotations

from typing import Any

import numpy as np

from bench.figures import ReportFigure, new_figure


def _cycles(data: Any) -> dict[str, np.ndarray] | None:
    if "hrg_selfcal_cycles" not in data:
        return None
    c = data.table("hrg_selfcal_cycles")
    return c if len(c["t_start_s"]) else None


def _rates(data: Any) -> dict[str, np.ndarray] | None:
    if "hrg_selfcal_rates" not in data:
        return None
    r = data.table("hrg_selfcal_rates")
    return r if len(r["t_s"]) else None


def gains_figure(c) -> ReportFigure:
    t_h = 0.5 * (c["t_start_s"] + c["t_end_s"]) / 3600.0
    fig, ax = new_figure(1, 1, height_in=3.0)
    ax = ax[0, 0]
    ax.errorbar(t_h, c["gain_diff_ppm"], yerr=1.96 * c["gain_diff_se_ppm"], fmt="o-", ms=3,
                label="identified g_x − g_y")
    ax.step(t_h, c["trim_diff_ppm"], where="mid", color="C1", label="trimmed out in the FPGA")
    ax.set_xlabel("time (h)")
    ax.set_ylabel("gain difference (ppm)")
    ax.legend(fontsize=7)
    return ReportFigure("hrg-selfcal_gains", "X/Y gain difference against time (paper fig. 3)", fig,
                        "Identified each cycle from the amplitude channel's θ̇ sin 4θ term, with its 95 % interval; "
                        "the step line is the part trimmed out in the FPGA's pickoff gain trims during the cycle.")


def damping_figure(c) -> ReportFigure:
    t_h = 0.5 * (c["t_start_s"] + c["t_end_s"]) / 3600.0
    fig, ax = new_figure(2, 1, height_in=4.0, sharex=True)
    ax[0, 0].errorbar(t_h, c["delta_inv_tau_per_s"] * 1e6, yerr=1.96e6 * c["delta_inv_tau_se_per_s"], fmt="o-", ms=3)
    ax[0, 0].set_ylabel("Δ(1/τ) (µ1/s)")
    ax[1, 0].errorbar(t_h, c["theta_tau_deg"], yerr=1.96 * c["theta_tau_se_deg"], fmt="o-", ms=3, color="C2")
    ax[1, 0].set_ylabel("θτ (deg)")
    ax[1, 0].set_xlabel("time (h)")
    return ReportFigure("hrg-selfcal_damping", "Damping anisotropy against time (paper fig. 4)", fig,
                        "Δ(1/τ) and its axis identified each forced-precession cycle (amplitude channel).")


def drift_figure(r, c) -> ReportFigure:
    fig, ax = new_figure(1, 1, height_in=3.2)
    ax = ax[0, 0]
    th = np.mod(r["theta_deg"], 90.0)
    ok = np.isfinite(r["plain_dph"])
    k = max(1, int(ok.sum() // 4000))
    ax.plot(th[ok][::k], r["plain_dph"][ok][::k], ".", ms=1, color="C0", alpha=0.4, label="measured (plain rate)")
    has = np.isfinite(r["selfcal_dph"]) & ok
    order = np.argsort(th[has])
    ax.plot(th[has][order], r["drift_dph"][has][order], "-", color="C3", lw=1.2, label="identified drift")
    ax.set_xlabel("wave angle mod 90 (deg)")
    ax.set_ylabel("rate (deg/h)")
    ax.legend(fontsize=7)
    return ReportFigure("hrg-selfcal_drift", "Drift against wave angle, measured and identified (paper fig. 5)", fig,
                        "The plain whole-angle rate −(θ̇ − command)/K against the wave angle, and the drift the "
                        "previous cycle's identification predicts (removed in the self-calibrated rate).")


def angle_figure(r) -> list[ReportFigure]:
    comp = r["selfcal_dph"]
    first = int(np.argmax(np.isfinite(comp)))
    t = r["t_s"][first:]
    c = comp[first:]
    dt = float(np.median(np.diff(t))) if len(t) > 1 else 1.0
    c = np.where(np.isfinite(c), c, np.nanmean(c))
    t_h = (t - t[0]) / 3600.0
    angle = np.cumsum(c) * dt / 3600.0
    mean = np.cumsum(c) / np.arange(1, len(c) + 1)
    k = max(1, len(t) // 4000)
    try:  # the envelope +-1.96 sqrt(D(t)) of the angle-error model fitted to this record (docs/selfcal.md s. 4)
        from bench.analysis.selfcal import fit_angle_error

        model = fit_angle_error(angle, dt)
        env = 1.96 * np.sqrt(model.increment_var_deg2(np.maximum(t[::k] - t[0], dt)))
    except ValueError:
        env = None
    fig, ax = new_figure(1, 1, height_in=3.0)
    ax[0, 0].plot(t_h[::k], angle[::k], lw=1.0)
    ax[0, 0].axhline(0.0, color="k", lw=0.5)
    if env is not None:
        ax[0, 0].plot(t_h[::k], env, color="C3", ls="--", lw=0.7)
        ax[0, 0].plot(t_h[::k], -env, color="C3", ls="--", lw=0.7)
    ax[0, 0].set_xlabel("time since compensation started (h)")
    ax[0, 0].set_ylabel("integrated angle error (deg)")
    f1 = ReportFigure("hrg-selfcal_angle", "Integrated angle error against time (paper fig. 6)", fig,
                      "The self-calibrated rate integrated (true input rate 0: axis east, at rest); dashed: "
                      "±1.96 √D(t), D the angle random walk plus bounded angle error fitted to the record "
                      "(flat when the angle error does not accumulate).")
    fig2, ax2 = new_figure(1, 1, height_in=3.0)
    ax2[0, 0].plot(t_h[::k], mean[::k], lw=1.0)
    ax2[0, 0].axhline(0.0, color="k", lw=0.5)
    if env is not None:
        tt = np.maximum(t[::k] - t[0], dt) / 3600.0
        ax2[0, 0].plot(t_h[::k], env / tt, color="C1", ls=":", lw=0.7)
        ax2[0, 0].plot(t_h[::k], -env / tt, color="C1", ls=":", lw=0.7)
    for y in (-0.018, 0.018):
        ax2[0, 0].axhline(y, color="C3", ls="--", lw=0.7)
    ax2[0, 0].set_ylim(-0.5, 0.5)
    ax2[0, 0].set_xlabel("time since compensation started (h)")
    ax2[0, 0].set_ylabel("mean bias since start (deg/h)")
    f2 = ReportFigure("hrg-selfcal_mean_bias", "Mean bias since start (paper fig. 7)", fig2,
                      "Running mean of the self-calibrated rate; dashed: ±0.018 deg/h (the paper's value after 10 h); "
                      "dotted: ±1.96 √D(t) / t from the fitted angle-error model.")
    return [f1, f2]


def figures(proc: Any, data: Any) -> list[ReportFigure]:
    """Every figure an hrg-selfcal run's results need."""
    c, r = _cycles(data), _rates(data)
    out: list[ReportFigure] = []
    if c is not None:
        out += [gains_figure(c), damping_figure(c)]
    if r is not None and c is not None:
        out.append(drift_figure(r, c))
    if r is not None and np.any(np.isfinite(r["selfcal_dph"])):
        out += angle_figure(r)
    return out
