"""table-spin figures: the table rate the procedure read against time, with the tolerance band."""

from __future__ import annotations

from typing import Any

from .figures import ReportFigure, axis_label, measurement, new_figure, table_figure
from .numbers import plain, sig


def figures(proc: Any, data: Any) -> list[ReportFigure]:
    """The held rate with its tolerance band, then the table's own status stream."""
    out: list[ReportFigure] = []
    if "hold" in data:
        tab = data.table("hold")
        t, rate = tab["t_s"], tab["rate_dps"]
        lo, hi = proc.rate_dps - proc.tolerance_dps, proc.rate_dps + proc.tolerance_dps
        specs = type(proc).param_specs()  # the parameters' declared units
        tol_u, rate_u = specs["tolerance_dps"].unit, specs["rate_dps"].unit
        fig, ax = new_figure(1, 1, height_in=2.8)
        a = ax[0, 0]
        a.axhspan(lo, hi, color="C2", alpha=0.15, label=f"tolerance ±{plain(proc.tolerance_dps)} {tol_u}")
        a.axhline(proc.rate_dps, color="C2", linewidth=0.8, label=f"command {plain(proc.rate_dps)} {rate_u}")
        a.plot(t, rate, "o-", color="C0", markersize=3, label="rate read while holding")
        m = measurement(data, "table_rate_dps")
        if m:
            a.axhline(m["value"], color="C3", linestyle="--", linewidth=0.9,
                      label=f"mean {sig(m['value'], 6)} {m.get('unit', '')}")
        span = max(hi - lo, float(rate.max() - rate.min()) if len(rate) else 0.0)
        mid = 0.5 * (lo + hi)
        a.set_ylim(min(mid - 0.75 * span, float(rate.min()) if len(rate) else lo),
                   max(mid + 0.75 * span, float(rate.max()) if len(rate) else hi))
        a.set_xlabel(axis_label(data, "hold", "t_s"))
        a.set_ylabel(axis_label(data, "hold", "rate_dps"))
        a.legend(loc="upper right", ncols=2)
        out.append(ReportFigure("table-spin_rate", "Table rate against time, with the tolerance band", fig,
                                f"{len(t)} readings while holding; pass band [{plain(lo)}, {plain(hi)}] {rate_u}."))
    return out + table_figure(data)
