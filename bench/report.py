"""A run's HTML report: identity, parameters, measurements against limits (and truth), and plots
of the raw streams and fits as inline SVG drawn from numpy (no plotting library needed)."""

from __future__ import annotations

import html
import math
from typing import Any

import numpy as np

MAX_POINTS = 1500
#: what a fit's curves are plotted against, in order of preference
_X_NAMES = ("t_s", "freq_hz", "drive_freq_hz", "theta_deg", "theta_rad")
_COLORS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#17becf", "#8c564b", "#e377c2")


def _decimate(x: np.ndarray, ys: list[np.ndarray]) -> tuple[np.ndarray, list[np.ndarray]]:
    step = max(1, int(math.ceil(len(x) / MAX_POINTS)))
    return x[::step], [y[::step] for y in ys]


def _cell(value: float, legend: dict[int, str] | None) -> str:
    """A table cell: a coded value by its meaning (the stream's legend), else the number."""
    if legend and value.is_integer() and int(value) in legend:
        return legend[int(value)]
    return f"{value:.6g}"


def svg_plot(
    x: np.ndarray,
    series: dict[str, np.ndarray],
    *,
    title: str,
    xlabel: str,
    width: int = 760,
    height: int = 260,
    logy: bool | None = None,
    markers: bool | None = None,
) -> str:
    """Plot of several series over x as an SVG string.  logy=None picks a log axis for positive
    data spanning more than two decades; markers=None draws points where x is not monotonic
    (e.g. drift against wave angle) and lines otherwise."""
    x = np.asarray(x, dtype=float)
    names = list(series)
    if x.size < 2 or not names:
        return f"<p><em>{html.escape(title)}: no data</em></p>"
    xd, ys = _decimate(x, [np.asarray(series[n], dtype=float) for n in names])
    if markers is None:
        dx = np.diff(xd[np.isfinite(xd)])
        markers = not (np.all(dx >= 0) or np.all(dx <= 0))
    allv = np.concatenate([y[np.isfinite(y)] for y in ys]) if ys else np.array([])
    if logy is None:
        logy = bool(allv.size and allv.min() > 0 and allv.max() / allv.min() > 100.0)
    if logy:
        ys = [np.where(y > 0, np.log10(np.where(y > 0, y, 1.0)), np.nan) for y in ys]
    finite = np.concatenate([y[np.isfinite(y)] for y in ys]) if ys else np.array([0.0])
    y0, y1 = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
    if y1 - y0 < 1e-300:
        y0, y1 = y0 - 0.5, y1 + 0.5
    x0, x1 = float(np.nanmin(xd)), float(np.nanmax(xd))
    if x1 - x0 < 1e-300:
        x1 = x0 + 1.0
    ml, mr, mt, mb = 70, 10, 24, 34
    pw, ph = width - ml - mr, height - mt - mb

    def sx(v):
        return ml + (v - x0) / (x1 - x0) * pw

    def sy(v):
        return mt + (1 - (v - y0) / (y1 - y0)) * ph

    out = [
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" font-size="11">',
        f'<text x="{ml}" y="15" font-weight="bold">{html.escape(title)}</text>',
        f'<rect x="{ml}" y="{mt}" width="{pw}" height="{ph}" fill="none" stroke="#888"/>',
    ]
    for frac in (0.0, 0.5, 1.0):
        yv = y0 + frac * (y1 - y0)
        xv = x0 + frac * (x1 - x0)
        label = f"{10.0 ** yv:.3g}" if logy else f"{yv:.4g}"
        out.append(f'<text x="{ml - 4}" y="{sy(yv) + 4:.1f}" text-anchor="end">{label}</text>')
        out.append(f'<text x="{sx(xv):.1f}" y="{height - 18}" text-anchor="middle">{xv:.4g}</text>')
    axis = f"{xlabel}   (log y)" if logy else xlabel
    out.append(f'<text x="{ml + pw / 2}" y="{height - 4}" text-anchor="middle">{html.escape(axis)}</text>')
    for i, (name, y) in enumerate(zip(names, ys, strict=True)):
        ok = np.isfinite(y) & np.isfinite(xd)
        pts = " ".join(f"{a:.1f},{b:.1f}" for a, b in zip(sx(xd[ok]), sy(y[ok]), strict=True))
        color = _COLORS[i % len(_COLORS)]
        if markers:
            out.extend(
                f'<circle cx="{a:.1f}" cy="{b:.1f}" r="1.6" fill="{color}"/>'
                for a, b in zip(sx(xd[ok]), sy(y[ok]), strict=True)
            )
        else:
            out.append(f'<polyline fill="none" stroke="{color}" stroke-width="1" points="{pts}"/>')
        out.append(f'<text x="{ml + 8 + 90 * i}" y="{mt + 14}" fill="{color}">{html.escape(name)}</text>')
    out.append("</svg>")
    return "\n".join(out)


def _table(rows: list[list[Any]], header: list[str]) -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in r) + "</tr>" for r in rows)
    return f"<table><tr>{head}</tr>{body}</table>"


def render_report(data: Any, run_row: dict[str, Any] | None = None) -> str:
    """HTML for one run from its raw file (a RunData) and, when known, its results-store row."""
    a = data.attrs
    result = a.get("result") or {}
    truth = data.truth or {}
    parts = [
        "<!doctype html><html><head><meta charset='utf-8'>",
        f"<title>gyrobench run {html.escape(str(a.get('run_id', '')))}</title>",
        "<style>body{font-family:sans-serif;margin:2em}table{border-collapse:collapse;margin:1em 0}"
        "td,th{border:1px solid #ccc;padding:3px 8px;text-align:left}.PASS{color:green}.FAIL,.ERROR{color:#c00}"
        ".MARGINAL{color:#b80}</style></head><body>",
        f"<h1>{html.escape(str(a.get('procedure', '')))} — run {html.escape(str(a.get('run_id', '')))}</h1>",
    ]
    outcome = a.get("outcome", "(unfinished)")
    parts.append(
        f"<p class='{html.escape(str(outcome))}'><b>{html.escape(str(outcome))}</b>: "
        f"{html.escape(str(a.get('end_reason', 'the run did not finish (killed?)')))}; safe state "
        f"{'confirmed' if a.get('safe_state') else 'NOT confirmed'}</p>"
    )
    incomplete = data.incomplete
    if incomplete:
        parts.append(
            f"<p class='ERROR'><b>INCOMPLETE RUN</b>: {html.escape(incomplete)}. The data, measurements and "
            "re-analyses below are from what was recorded before the run ended.</p>"
        )
    ident = [
        [k, a.get(k, "")]
        for k in (
            "station_id",
            "simulated",
            "seed",
            "started_at",
            "finished_at",
            "simulated_s",
            "wall_s",
            "software_version",
            "operator",
            "duts",
        )
    ]
    parts.append(_table(ident, ["", ""]))
    parts.append("<h2>Parameters</h2>" + _table([[k, v] for k, v in data.params.items()], ["name", "value"]))
    meas = result.get("measurements") or {m["name"]: m for m in data.measurements()}
    rows = []
    for name, m in meas.items():
        lim = m.get("limits") if "limits" in m else [m.get("low"), m.get("high")]
        t = truth.get(name, "")
        rows.append([name, m.get("value"), m.get("unit", ""), m.get("ci95"), lim, m.get("outcome"), t])
    if run_row is not None:
        for m in run_row.get("measurements", []):
            if m["source"] == "analyze":
                rows.append(
                    [
                        m["name"] + (" (re-analysis, incomplete run)" if incomplete else " (re-analysis)"),
                        m["value"],
                        m["unit"],
                        [m["ci95_low"], m["ci95_high"]],
                        [m["low"], m["high"]],
                        m["outcome"],
                        truth.get(m["name"], ""),
                    ]
                )
    parts.append(
        "<h2>Measurements</h2>" + _table(rows, ["name", "value", "unit", "ci95", "limits", "outcome", "truth"])
    )
    fits = data.fits()
    if fits:
        parts.append("<h2>Fits</h2>")
    for name, curves in fits.items():
        xk = next((k for k in _X_NAMES if k in curves), next(iter(curves), None))
        if xk is None:
            continue
        ys = {k: v for k, v in curves.items() if k != xk and np.shape(v) == np.shape(curves[xk])}
        parts.append(svg_plot(curves[xk], ys, title=f"fit: {name}", xlabel=xk))
    parts.append("<h2>Raw data</h2>")
    for stream in data.streams():
        tab = data.table(stream)
        cols = [c for c in tab if c not in ("t_s", "index")]
        x = tab.get("t_s", np.arange(len(next(iter(tab.values())))) if tab else np.array([]))
        units, legends = data.units(stream), data.legends(stream)
        if len(x) < 10:  # bookkeeping streams (windows, settings): a table says more than a plot
            rows = [[_cell(float(tab[c][i]), legends.get(c)) for c in tab] for i in range(len(x))]
            heads = [f"{c} ({units[c]})" if units.get(c) not in ("", "1") else c for c in tab]
            parts.append(f"<h3>{html.escape(stream)}</h3>" + _table(rows, heads))
            continue
        parts.append(svg_plot(x, {c: tab[c] for c in cols[:6]}, title=f"{stream} ({len(x)} rows)", xlabel="t (s)"))
        if stream == "fpga" and all(c in tab for c in ("cx", "sx", "cy", "sy")):
            e = tab["cx"] ** 2 + tab["sx"] ** 2 + tab["cy"] ** 2 + tab["sy"] ** 2
            parts.append(
                svg_plot(x, {"E = cx²+sx²+cy²+sy²": e}, title="fpga: energy E", xlabel="t (s)", logy=True)
            )
    log = data.log()
    if log:
        parts.append(
            "<h2>Log</h2>"
            + _table([[f"{r['t_sim_s']:.3f}", r["level"], r["msg"]] for r in log[-200:]], ["t (s)", "level", "message"])
        )
    parts.append("</body></html>")
    return "\n".join(parts)
