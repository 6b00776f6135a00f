"""table-spin figures: the table rate the procedure read against time, with the tolerance band."""

from __future__ import annotations

from typing import Any

from bench.figures import ReportFigure, axis_label, measurement, new_figure, table_figure
from bench.numbers import plain, sig


def figures(proc: Any, data: Any) -> list[ReportFigure]:
    """The held rate with its tolerance band, then the table's own status stream."""
    out: list[ReportFigure] = []
    if "hold" in data:
        tab = data.table("hold")
        t, rate = tab["t_s"], tab["rate_dps"]
        lo, hi = proc.rate_dps - proc.tolerance_dps, proc.rate_dps + proc.tolerance_dps
        specs = type(proc).param_specs()  # the parameters' declared units
        tol_u, rate_u = specs["tolerance_dps"].unit, specs["rate_dps"].unit
        fig, ax = new_figure(2, 1, height_in=3.9, sharex=True, gridspec_kw={"height_ratios": [2.2, 1.3]})
        a, dev = ax[0, 0], ax[1, 0]
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
        a.set_ylabel(axis_label(data, "hold", "rate_dps"))
        # beneath, on its own scale: what the band hides, the readings' departure from the command
        dev.plot(t, rate - proc.rate_dps, "o-", color="C0", markersize=3)
        if m:
            dev.axhline(m["value"] - proc.rate_dps, color="C3", linestyle="--", linewidth=0.9)
        dev.axhline(0.0, color="C2", linewidth=0.8)
        dev.set_ylabel(axis_label(data, "hold", "rate_dps", quantity="rate − command"))
        dev.set_xlabel(axis_label(data, "hold", "t_s"))
        fig.legend(*a.get_legend_handles_labels(), loc="outside upper center", ncols=4)  # never over the band
        out.append(ReportFigure("table-spin_rate", "Table rate against time, with the tolerance band", fig,
                                f"{len(t)} readings while holding; pass band [{plain(lo)}, {plain(hi)}] {rate_u}. "
                                "Beneath, the readings minus the command on their own scale."))
    return out + table_figure(data)
