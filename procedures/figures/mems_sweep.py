"""mems-sweep figures: amplitude and phase against frequency per channel (up and down sweeps,
measured points over the linear, cubic and quintic model curves), the 1:1 polar plots, and the
residuals of each model."""

from __future__ import annotations

from typing import Any

import numpy as np

from bench.figures import ReportFigure, axis_label, equal_aspect, new_figure
from bench.numbers import sig

MODELS = ("linear", "cubic", "quintic")
_COLOR = {"linear": "C2", "cubic": "C3", "quintic": "C4"}
_STYLE = {"linear": ":", "cubic": "-", "quintic": "--"}
GRID_POINTS = 61


def _branches(fit: Any, freqs_up: np.ndarray) -> dict[str, np.ndarray]:
    """Steady states of a model along an upward and a downward sweep (the two hysteresis branches)."""
    up = fit.response(freqs_up).q
    if fit.model == "linear":  # one steady state per frequency: no hysteresis
        return {"up": up, "down": up}
    down = fit.response(freqs_up[::-1]).q[::-1]
    return {"up": up, "down": down}


def _amp_phase(q: np.ndarray, ch: int) -> tuple[np.ndarray, np.ndarray]:
    a, b = q[:, 2 * ch], q[:, 2 * ch + 1]
    return np.hypot(a, b), np.degrees(np.arctan2(b, a))


def sweep_models(proc: Any, data: Any) -> dict[str, Any]:
    """The sweep's steady states and the three identified models evaluated on it and on a grid."""
    from bench.analysis.maslov import choose_model, identify_forced

    tab = data.table("sweep")
    f, d, q = tab["freq_hz"], tab["direction"], np.column_stack([tab[c] for c in ("q1", "p1", "q2", "p2")])
    fits = {m: identify_forced(f, *q.T, natural_freq_hz=proc.natural_freq_hz, model=m,
                               bryan_factor=proc.bryan_factor) for m in MODELS}  # as the procedure's analysis
    chosen = choose_model({m: fit.sigma for m, fit in fits.items()}, proc.improvement)
    # the measured frequencies are on the grid, so each model is solved once per branch
    grid = np.union1d(np.linspace(f.min(), f.max(), GRID_POINTS), f)
    out = {"f": f, "dir": d, "q": q, "grid": grid, "chosen": chosen, "sigma": {m: fits[m].sigma for m in MODELS},
           "curves": {}, "at_points": {},
           "label": lambda c, **kw: axis_label(data, "sweep", c, **kw)}  # quantity and unit as declared
    idx = np.searchsorted(grid, f)
    for m in MODELS:
        br = out["curves"][m] = _branches(fits[m], grid)
        out["at_points"][m] = np.where((d < 0)[:, None], br["down"][idx], br["up"][idx])
    return out


def _sweep_figure(s: dict[str, Any], ch: int) -> ReportFigure:
    fig, ax = new_figure(2, 1, height_in=4.6, sharex=True)
    amp_ax, ph_ax = ax[0, 0], ax[1, 0]
    for m in MODELS:
        for branch in ("up", "down"):
            a, p = _amp_phase(s["curves"][m][branch], ch)
            lab = f"{m} model" + (" (chosen)" if m == s["chosen"] else "") if branch == "up" else None
            amp_ax.plot(s["grid"], a, _STYLE[m], color=_COLOR[m], label=lab, linewidth=1.1)
            ph_ax.plot(s["grid"], p, _STYLE[m], color=_COLOR[m], linewidth=1.1)
    for sel, mk, name, col in ((s["dir"] > 0, "^", "measured, sweep up", "C0"),
                               (s["dir"] < 0, "v", "measured, sweep down", "C1")):
        if sel.any():
            a, p = _amp_phase(s["q"][sel], ch)
            amp_ax.plot(s["f"][sel], a, mk, color=col, markersize=4, fillstyle="none", label=name)
            ph_ax.plot(s["f"][sel], p, mk, color=col, markersize=4, fillstyle="none")
    amp_ax.set_ylabel(s["label"]("amplitude" if ch == 0 else "amplitude_y"))
    ph_ax.set_ylabel(s["label"]("phase_deg" if ch == 0 else "phase_y_deg"))
    ph_ax.set_xlabel(s["label"]("freq_hz"))
    fig.legend(loc="outside upper center", ncols=5)  # above the axes: never over the resonance
    n = "1 (q1, p1)" if ch == 0 else "2 (q2, p2)"
    return ReportFigure(f"mems-sweep_channel{ch + 1}", f"Channel {n}: amplitude and phase against frequency", fig,
                        "Steady states measured on the up and down sweeps (markers) and the steady states of each "
                        "identified model, solved along an upward and a downward sweep (lines).")


def _polar_figure(s: dict[str, Any]) -> ReportFigure:
    fig, ax = new_figure(1, 2, height_in=3.9)
    for ch in (0, 1):
        a = ax[0, ch]
        for m in MODELS:
            for branch in ("up", "down"):
                q = s["curves"][m][branch]
                a.plot(q[:, 2 * ch], q[:, 2 * ch + 1], _STYLE[m], color=_COLOR[m], linewidth=1.1,
                       label=f"{m} model" if branch == "up" else None)
        for sel, mk, name, col in ((s["dir"] > 0, "^", "sweep up", "C0"), (s["dir"] < 0, "v", "sweep down", "C1")):
            if sel.any():
                a.plot(s["q"][sel, 2 * ch], s["q"][sel, 2 * ch + 1], mk, color=col, markersize=4, fillstyle="none",
                       label=name)
        equal_aspect(a)
        qn, pn = ("q1", "p1") if ch == 0 else ("q2", "p2")
        a.set_xlabel(s["label"](qn))
        a.set_ylabel(s["label"](pn))
        a.set_title(f"channel {ch + 1}")
    fig.legend(*ax[0, 0].get_legend_handles_labels(), loc="outside upper center", ncols=5)
    return ReportFigure("mems-sweep_polar", "Polar plots (1:1): in-phase against quadrature response", fig,
                        "Equal scales on both axes, so a circle stays a circle.")


def _residual_figure(s: dict[str, Any]) -> ReportFigure:
    fig, ax = new_figure(len(MODELS), 2, height_in=1.0 + 1.3 * len(MODELS), sharex=True)
    for i, m in enumerate(MODELS):
        for ch in (0, 1):
            a_meas, _ = _amp_phase(s["q"], ch)
            a_mod, _ = _amp_phase(s["at_points"][m], ch)
            for sel, mk, col in ((s["dir"] > 0, "^", "C0"), (s["dir"] < 0, "v", "C1")):
                ax[i, ch].plot(s["f"][sel], (a_meas - a_mod)[sel], mk, color=col, markersize=3.5, fillstyle="none")
            ax[i, ch].axhline(0.0, color=_COLOR[m], linewidth=0.9)
            ax[i, ch].set_title(f"{m} model, channel {ch + 1}" + (f"  (fit σ = {sig(s['sigma'][m], 3)})"
                                                                   if ch == 0 else ""), fontsize=8.5)
        ax[i, 0].set_ylabel(s["label"]("amplitude", quantity="ΔA"))
    for ch in (0, 1):
        ax[-1, ch].set_xlabel(s["label"]("freq_hz"))
    return ReportFigure("mems-sweep_residuals", "Residuals of each model: measured minus model amplitude", fig,
                        "Amplitude measured minus the model's steady state on the branch of the point's sweep "
                        "direction (▲ up, ▼ down); each model on its own scale.")


def figures(proc: Any, data: Any) -> list[ReportFigure]:
    """Every figure a mems-sweep run's results need, in the report's order."""
    if "sweep" not in data or len(data.table("sweep").get("t_s", ())) < 5:
        return []
    s = sweep_models(proc, data)
    return [_sweep_figure(s, 0), _sweep_figure(s, 1), _polar_figure(s), _residual_figure(s)]
