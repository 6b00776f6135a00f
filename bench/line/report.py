"""`gyrobench line report`: yield by lot, day and station; each limited measurement's histogram with
its limits and its Cp / Cpk; a control chart of each over time; every unit's history across attempts.
One HTML page (figures as inline SVG, in the style of bench/reporting) and, with --pdf, a PDF."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from .stats import capability, final_attempts, yield_by

TEMPLATES = Path(__file__).with_name("templates")
MAX_HISTORY_UNITS = 200  # units listed with their history (the rest are in the database)


def summarize(db: Any, lot: str | None = None) -> dict[str, Any]:
    """Everything the report shows, as numbers (tests cross-check these against the records)."""
    attempts = db.attempts(lot=lot)
    meas = db.measurements(lot=lot)
    last_ids = {(a["serial"], a["attempt"]) for a in final_attempts(attempts).values()}
    by_name: dict[str, list[dict[str, Any]]] = {}
    for m in meas:
        by_name.setdefault(m["name"], []).append(m)
    measures = []
    for name, rows in sorted(by_name.items()):
        final = [r for r in rows if (r["serial"], r["attempt"]) in last_ids]
        low, high = rows[-1]["low"], rows[-1]["high"]
        cap = capability([r["value"] for r in final], low, high)
        counts = {o: sum(1 for r in final if r["outcome"] == o) for o in ("PASS", "MARGINAL", "FAIL", "ERROR")}
        measures.append({"name": name, "unit": rows[-1]["unit"], "low": low, "high": high, "rule": rows[-1]["rule"],
                         "rows": rows, "final": final, "counts": counts, **cap})
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
    }


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
    hist = ReportFigure(f"hist-{measure['name']}", measure["name"], fig).svg()
    fig2, axes2 = new_figure(1, 1, height_in=2.4, width_in=6.0)
    ax = axes2[0, 0]
    all_vals = np.array([np.nan if r["value"] is None else r["value"] for r in measure["rows"]], dtype=float)
    ax.plot(np.arange(1, all_vals.size + 1), all_vals, ".-", ms=3, lw=0.6, color="#333")
    if measure["mean"] is not None and measure["sigma"]:
        mu, sd = measure["mean"], measure["sigma"]
        ax.axhline(mu, color="#1a7f1a", lw=1, label="mean")
        for k in (-3, 3):
            ax.axhline(mu + k * sd, color="#b80", lw=1, ls=":", label="mean ± 3 sigma" if k > 0 else None)
    for lim in (measure["low"], measure["high"]):
        if lim is not None:
            ax.axhline(lim, color="#c00", ls="--", lw=1.2)
    ax.set_xlabel("attempt, in time order")
    ax.set_ylabel(measure["name"] + unit)
    _legend(ax)
    chart = ReportFigure(f"chart-{measure['name']}", measure["name"], fig2).svg()
    return hist, chart


def render_html(summary: dict[str, Any]) -> str:
    import jinja2

    env = jinja2.Environment(loader=jinja2.FileSystemLoader(TEMPLATES), autoescape=True)
    for m in summary["measures"]:
        m["hist_svg"], m["chart_svg"] = _figures(m)
    units = sorted(summary["history"].items())
    return env.get_template("line_report.html.j2").render(
        s=summary, units=units[:MAX_HISTORY_UNITS], more_units=max(0, len(units) - MAX_HISTORY_UNITS),
        fmt=_fmt, pct=_pct)


def _fmt(x: Any) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "—"
    return f"{x:.4g}" if isinstance(x, float) else str(x)


def _pct(x: float) -> str:
    return "—" if x is None or not math.isfinite(x) else f"{100 * x:.1f} %"


def write_line_report(db: Any, *, lot: str | None = None, output: str | Path | None = None,
                      pdf: bool = False, runs_dir: str | Path = "runs") -> list[Path]:
    """The HTML report (and with pdf the PDF beside it); their paths."""
    from bench.pdf import require_weasyprint, write_pdf

    if pdf:
        require_weasyprint()  # a missing PDF library is said before anything is written
    summary = summarize(db, lot)
    out = Path(output) if output else Path(runs_dir) / "line" / (f"report-{lot}.html" if lot else "report.html")
    out.parent.mkdir(parents=True, exist_ok=True)
    html = render_html(summary)
    out.write_text(html, encoding="utf-8")
    paths = [out]
    if pdf:
        paths.append(write_pdf(html, out.with_suffix(".pdf")))
    return paths
