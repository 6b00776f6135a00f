"""cvg-allan figures: the log-log Allan deviation with its chi-squared band, the IEEE Std 952 slope
lines through the read-offs (-1/2: N, 0: 0.664 B, +1/2: K) and the read-off points."""

from __future__ import annotations

from typing import Any

import numpy as np

from bench.figures import ReportFigure, measurement, new_figure
from bench.numbers import with_interval

FLOOR = 0.664


def allan_figure(data: Any) -> list[ReportFigure]:
    if "cvg_allan_curve" not in data:
        return []
    c = data.table("cvg_allan_curve")
    tau, adev, lo, hi = c["tau_s"], c["adev_dph"], c["adev_low_dph"], c["adev_high_dph"]
    if len(tau) == 0:
        return []
    fig, ax = new_figure(1, 1, height_in=4.2)
    ax = ax[0, 0]
    ax.fill_between(tau, lo, hi, color="C0", alpha=0.2, linewidth=0, label="95 % interval (chi-squared)")
    ax.loglog(tau, adev, "o-", color="C0", markersize=3, label="overlapping Allan deviation")
    t_line = np.geomspace(tau[0], tau[-1], 50)
    rows, notes = [], []
    terms = (
        ("arw_deg_rth", "N", "deg/√h", lambda v: v * 60.0 / np.sqrt(t_line), "−1/2", "C1"),
        ("bias_instability_dph", "B", "deg/h", lambda v: np.full_like(t_line, FLOOR * v), "0", "C2"),
        ("rrw_dph_rth", "K", "deg/h/√h", lambda v: v / 60.0 * np.sqrt(t_line / 3.0), "+1/2", "C3"),
    )
    for name, sym, unit, line, slope, color in terms:
        m = measurement(data, name)
        if not m or m.get("value") is None or not np.isfinite(m["value"]) or m["value"] <= 0:
            continue
        ax.loglog(t_line, line(m["value"]), "--", color=color, linewidth=1.0, label=f"slope {slope}: {sym}")
        v, ci = with_interval(m["value"], m.get("ci95"))
        rows.append([sym, f"{v} {unit}", f"{ci} {unit}"])
    ax.set_ylim(max(np.min(lo[lo > 0]) / 2 if np.any(lo > 0) else np.min(adev) / 2, 1e-300), np.max(hi) * 2)
    _label_every_decade_part(ax)
    ax.set_xlabel("τ (s)")
    ax.set_ylabel("σ(τ) (deg/h)")
    ax.grid(True, which="both", linewidth=0.3, alpha=0.5)
    ax.legend(fontsize=7, loc="best")
    notes.append("Overlapping Allan deviation of the rate output (whole-angle: the wave angle's derivative "
                 "over −K), octave-spaced τ, with its 95 % chi-squared band; the dashed lines are the annex's "
                 "slopes through the read-offs: N/√τ, 0.664 B, K√(τ/3).")
    table = (["term", "value", "95 % interval"], rows) if rows else None
    return [ReportFigure("cvg-allan_adev", "Allan deviation of the rate output", fig, " ".join(notes), table)]


def _label_every_decade_part(ax: Any) -> None:
    """y ticks labelled at 1, 2 and 5 of every decade, as plain numbers (0.05, 0.2, 1): a curve
    within one decade below 1 deg/h (the minimum, the bias-instability line) gets labels there."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    ax.yaxis.set_major_locator(LogLocator(base=10.0, subs=(1.0, 2.0, 5.0)))
    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _pos: f"{v:.6g}"))
    ax.yaxis.set_minor_formatter(NullFormatter())


def figures(proc: Any, data: Any) -> list[ReportFigure]:
    """Every figure a cvg-allan run's results need."""
    return allan_figure(data)
