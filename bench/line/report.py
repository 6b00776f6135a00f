"""`gyrobench line report`: yield by lot, day and station; each limited measurement, grouped by product,
sequence and procedure, with its histogram and limits, Cp / Cpk with confidence intervals over units,
and an individuals control chart (Shewhart limits from the moving range) in units' time order; the
golden units' drift; every unit's history across attempts.  One HTML page (figures as inline SVG, in
the style of bench/reporting) and, with --pdf, a PDF."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from .stats import capability, final_attempts, individuals_chart, yield_by

TEMPLATES = Path(__file__).with_name("templates")
MAX_HISTORY_UNITS = 200  # units listed with their history (the rest are in the database)


def per_unit(rows: list[dict[str, Any]], last_ids: set[tuple[str, int]]) -> list[dict[str, Any]]:
    """One row per unit, from its final attempt (its last value there), in the time order the units
    were tested: the capability's and the control chart's n is units, not rows."""
    by_unit: dict[str, dict[str, Any]] = {}
    for r in rows:
        if (r["serial"], r["attempt"]) in last_ids:
            by_unit.pop(r["serial"], None)
            by_unit[r["serial"]] = r
    return sorted(by_unit.values(), key=lambda r: (r.get("ended_at") or "", r["serial"]))


def summarize(db: Any, lot: str | None = None, runs_dir: str | Path | None = None) -> dict[str, Any]:
    """Everything the report shows, as numbers (tests cross-check these against the records)."""
    attempts = db.attempts(lot=lot)
    meas = db.measurements(lot=lot)
    last_ids = {(a["serial"], a["attempt"]) for a in final_attempts(attempts).values()}
    groups: dict[tuple[str, str, str, str], list[dict[str, Any]]] = {}
    for m in meas:
        key = (m.get("product") or "", m.get("sequence") or "", m.get("procedure") or "", m["name"])
        groups.setdefault(key, []).append(m)
    measures = []
    for (product, sequence, procedure, name), rows in sorted(groups.items()):
        final = per_unit(rows, last_ids)
        low, high = rows[-1]["low"], rows[-1]["high"]
        values = [r["value"] for r in final]
        cap = capability(values, low, high)
        counts = {o: sum(1 for r in final if r["outcome"] == o) for o in ("PASS", "MARGINAL", "FAIL", "ERROR")}
        measures.append({"name": name, "product": product, "sequence": sequence, "procedure": procedure,
                         "unit": rows[-1]["unit"], "low": low, "high": high, "rule": rows[-1]["rule"],
                         "rows": rows, "final": final, "counts": counts, "units": len(final),
                         "chart": individuals_chart(values), **cap})
    history: dict[str, list[dict[str, Any]]] = {}
    for a in attempts:
        history.setdefault(a["serial"], []).append(a)
    return {
        "lot": lot,
        "attempts": attempts,
        "units": len(history),
        "by_lot": yield_by(attempts, lambda a: a["lot"] or "-"),
        "by_day": yield_by(attempts, lambda a: a["ended_at"][:10]),
        "by_station": yield_by(attempts, lambda a: a["station"]),
        "measures": measures,
        "history": history,
        "golden": golden_checks(runs_dir) if runs_dir is not None else [],
    }


def golden_checks(runs_dir: str | Path) -> list[dict[str, Any]]:
    """The golden-unit checks logged under RUNS_DIR/line/stations/ (every station), oldest first:
    one row per check and reference, its drift and limit."""
    from .station_state import read_log

    out = []
    for e in read_log(runs_dir):
        if e.get("event") != "golden":
            continue
        for d in e.get("drifts") or ():
            out.append({"at": e["at"], "station": e["station"], "serial": e.get("serial", ""), "name": d["name"],
                        "unit": d.get("unit", ""), "drift": d.get("drift"), "limit": d.get("limit"),
                        "ok": d.get("ok"), "held": e.get("held")})
    return out


def _golden_figure(rows: list[dict[str, Any]]) -> str:
    """Each golden reference's drift / its limit by check, in time order (beyond ±1 locks the station)."""
    from bench.figures import ReportFigure, new_figure

    fig, axes = new_figure(1, 1, height_in=2.4, width_in=6.0)
    ax = axes[0, 0]
    series: dict[tuple[str, str, str], list[float]] = {}
    for r in rows:
        ratio = math.nan if r["drift"] is None or not r["limit"] else r["drift"] / r["limit"]
        series.setdefault((r["station"], r["serial"], r["name"]), []).append(ratio)
    for (station, serial, name), ys in series.items():
        ax.plot(np.arange(1, len(ys) + 1), ys, "o-", ms=4, lw=0.8, label=f"{station} {serial} {name}")
    for k in (-1, 1):
        ax.axhline(k, color="#c00", ls="--", lw=1.2, label="limit (locks the station)" if k > 0 else None)
    ax.set_xlabel("golden check, in time order")
    ax.set_ylabel("drift / its limit")
    _legend(ax)
    return ReportFigure("golden-drift", "golden unit drift", fig).svg()


def _legend(ax: Any) -> None:
    """A legend when something is labelled (a measurement without limits or spread has nothing:
    matplotlib would warn "No artists with labels found")."""
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=7, loc="best")


def _figures(measure: dict[str, Any]) -> tuple[str, str]:
    """(histogram, control chart) of one measurement as inline SVG."""
    from bench.figures import ReportFigure, new_figure

    unit = f" ({measure['unit']})" if measure["unit"] else ""
    vals = np.array([r["value"] for r in measure["final"] if r["value"] is not None and math.isfinite(r["value"])])
    fig, axes = new_figure(1, 1, height_in=2.4, width_in=6.0)
    ax = axes[0, 0]
    if vals.size:
        ax.hist(vals, bins=min(40, max(5, int(np.sqrt(vals.size)))), color="#4a7fb5", alpha=0.85)
    for lim, lab in ((measure["low"], "low"), (measure["high"], "high")):
        if lim is not None:
            ax.axvline(lim, color="#c00", ls="--", lw=1.2, label=f"{lab} limit {lim:g}")
    ax.set_xlabel(measure["name"] + unit)
    ax.set_ylabel("units")
    _legend(ax)
    tag = f"{measure['procedure']}-{measure['name']}-{measure['sequence']}"
    hist = ReportFigure(f"hist-{tag}", measure["name"], fig).svg()
    fig2, axes2 = new_figure(1, 1, height_in=2.4, width_in=6.0)
    ax = axes2[0, 0]
    vals_t = np.array([np.nan if r["value"] is None else r["value"] for r in measure["final"]], dtype=float)
    k = np.arange(1, vals_t.size + 1)
    ax.plot(k, vals_t, ".-", ms=3, lw=0.6, color="#333", label="unit (final attempt)")
    ch = measure["chart"]
    if ch["center"] is not None:
        ax.axhline(ch["center"], color="#1a7f1a", lw=1, label="mean")
        if ch["sigma_within"]:
            ax.axhline(ch["ucl"], color="#b80", lw=1, ls=":", label="UCL/LCL = mean ± 2.66 MR-bar")
            ax.axhline(ch["lcl"], color="#b80", lw=1, ls=":")
            out = [i for i in ch["outside"] if i < vals_t.size]
            if out:
                ax.plot(k[out], vals_t[out], "o", mfc="none", mec="#c00", ms=7, label="beyond a control limit")
    for lim in (measure["low"], measure["high"]):
        if lim is not None:
            ax.axhline(lim, color="#c00", ls="--", lw=1.2)
    ax.set_xlabel("unit, in the time order tested")
    ax.set_ylabel(measure["name"] + unit)
    _legend(ax)
    chart = ReportFigure(f"chart-{tag}", measure["name"], fig2).svg()
    return hist, chart


def render_html(summary: dict[str, Any]) -> str:
    import jinja2

    env = jinja2.Environment(loader=jinja2.FileSystemLoader(TEMPLATES), autoescape=True)
    for m in summary["measures"]:
        m["hist_svg"], m["chart_svg"] = _figures(m)
    units = sorted(summary["history"].items())
    summary["golden_svg"] = _golden_figure(summary["golden"]) if summary.get("golden") else ""
    return env.get_template("line_report.html.j2").render(
        s=summary, units=units[:MAX_HISTORY_UNITS], more_units=max(0, len(units) - MAX_HISTORY_UNITS),
        fmt=_fmt, pct=_pct, ci=_ci)


def _fmt(x: Any) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "—"
    return f"{x:.4g}" if isinstance(x, float) else str(x)


def _ci(pair: Any) -> str:
    return "" if not pair else f"[{pair[0]:.3g}, {pair[1]:.3g}]"


def _pct(x: float) -> str:
    return "—" if x is None or not math.isfinite(x) else f"{100 * x:.1f} %"


def write_line_report(db: Any, *, lot: str | None = None, output: str | Path | None = None,
                      pdf: bool = False, runs_dir: str | Path = "runs") -> list[Path]:
    """The HTML report (and with pdf the PDF beside it); their paths."""
    from bench.pdf import require_weasyprint, write_pdf

    if pdf:
        require_weasyprint()  # a missing PDF library is said before anything is written
    summary = summarize(db, lot, runs_dir)
    out = Path(output) if output else Path(runs_dir) / "line" / (f"report-{lot}.html" if lot else "report.html")
    out.parent.mkdir(parents=True, exist_ok=True)
    html = render_html(summary)
    out.write_text(html, encoding="utf-8")
    paths = [out]
    if pdf:
        paths.append(write_pdf(html, out.with_suffix(".pdf")))
    return paths
