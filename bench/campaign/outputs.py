"""What a campaign leaves beside its results: a Parquet file of every run's values and truths
(pyarrow), an HTML report with figures (coverage against the binomial band, error histograms,
error against a varied parameter; matplotlib), and the summary as a rich table or JSON."""

from __future__ import annotations

import base64
import html
import io
import math
from pathlib import Path
from typing import Any

import numpy as np

from .summary import NOT_MEASURED, MeasurementSummary


def table_rows(results: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """One row a run and measurement (a failed run: one row with its error), in run order."""
    rows = []
    varied_keys = sorted({k for r in results for k in r.get("varied", {})})
    # a varied column holds numbers, or (a grid of names: method = [...]) text
    as_text = {k for k in varied_keys if not all(_is_number(r.get("varied", {}).get(k)) for r in results)}
    for r in sorted(results, key=lambda r: r["index"]):
        varied = r.get("varied", {})
        base = {"run_id": r["run_id"], "index": r["index"], "procedure": r["procedure"], "seed": r["seed"],
                "outcome": r["outcome"], "error_text": r.get("error") or "", "wall_s": r.get("wall_s"),
                "raw_file": r.get("raw_file"),
                **{k: str(varied.get(k)) if k in as_text else _num(varied.get(k)) for k in varied_keys}}
        values = r.get("values") or {}
        if not values:
            rows.append({**base, "measurement": None, "unit": None, "value": None, "ci95_low": None,
                         "ci95_high": None, "truth": None, "error": None, "crlb": None})
        for name, value in values.items():
            ci = (r.get("ci95") or {}).get(name) or (None, None)
            truth = (r.get("truth") or {}).get(name)
            err = value - truth if value is not None and truth is not None else None
            rows.append({**base, "measurement": name, "unit": (r.get("units") or {}).get(name, ""),
                         "value": _num(value), "ci95_low": _num(ci[0]), "ci95_high": _num(ci[1]),
                         "truth": _num(truth), "error": _num(err), "crlb": _num((r.get("crlb") or {}).get(name))})
    return rows


def _is_number(x: Any) -> bool:
    return x is None or (isinstance(x, int | float) and not isinstance(x, bool))


def _num(x: Any) -> float | None:
    return None if x is None else float(x)


def write_parquet(results: list[dict[str, Any]], path: Path) -> Path:
    """Every run's values, intervals and truths as a Parquet file (one row a run and measurement)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    pq.write_table(pa.Table.from_pylist(table_rows(results)), path)
    return path


def summary_table(summary: list[MeasurementSummary], title: str) -> Any:
    """The summary as a rich Table."""
    from rich.table import Table

    t = Table(title=title)
    for col in ("measurement", "unit", "n", "bias", "+-95%", "std", "std/CRLB", "coverage", "band", "in band"):
        t.add_column(col, justify="left" if col in ("measurement", "unit") else "right")
    for s in summary:
        band = "" if s.band_low is None else f"[{s.band_low:.3f}, {s.band_high:.3f}]"
        t.add_row(s.name, s.unit, str(s.n), _g(s.bias), _g(s.bias_ci95), _g(s.std), _g(s.std_over_crlb, 3),
                  "" if s.coverage is None else f"{s.coverage:.3f}", band,
                  "" if s.covered is None else ("yes" if s.covered else "NO"))
    return t


def _g(x: float | None, digits: int = 4) -> str:
    return "" if x is None or not math.isfinite(x) else f"{x:.{digits}g}"


def _png(fig: Any) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    return base64.b64encode(buf.getvalue()).decode()


def _coverage_figure(summary: list[MeasurementSummary]) -> str | None:
    from matplotlib.figure import Figure

    rows = [s for s in summary if s.coverage is not None]
    if not rows:
        return None
    fig = Figure(figsize=(7, 0.35 * len(rows) + 1.5))
    ax = fig.add_subplot()
    y = np.arange(len(rows))
    for i, s in enumerate(rows):
        ax.plot([s.band_low, s.band_high], [i, i], color="0.7", lw=6, solid_capstyle="butt")
        ax.plot(s.coverage, i, "o", color="C0" if s.covered else "C3")
    ax.axvline(0.95, color="k", lw=0.8, ls="--")
    ax.invert_yaxis()  # the first measurement on top, as in the table
    ax.set_yticks(y, [s.name for s in rows])
    ax.set_xlabel("coverage of the 95 % interval (grey: binomial band)")
    fig.tight_layout()
    return _png(fig)


def _errors(results: list[dict[str, Any]], name: str) -> tuple[np.ndarray, list[dict[str, Any]]]:
    used = [r for r in sorted(results, key=lambda r: r["index"]) if r["outcome"] not in NOT_MEASURED
            and (r.get("values") or {}).get(name) is not None and (r.get("truth") or {}).get(name) is not None]
    return np.array([r["values"][name] - r["truth"][name] for r in used], dtype=float), used


def _varied_key(results: list[dict[str, Any]]) -> str | None:
    """The varied parameter with the most distinct values (None: nothing varied)."""
    keys = sorted({k for r in results for k in r.get("varied", {})})
    spread = {k: len({repr(r.get("varied", {}).get(k)) for r in results}) for k in keys}
    best = max(keys, key=lambda k: spread[k], default=None)
    return best if best is not None and spread[best] > 1 else None


def _measurement_figure(results: list[dict[str, Any]], s: MeasurementSummary, key: str | None) -> str | None:
    from matplotlib.figure import Figure

    err, used = _errors(results, s.name)
    err = err[np.isfinite(err)]
    if err.size == 0:
        return None
    fig = Figure(figsize=(9 if key else 4.5, 3.2))
    ax = fig.add_subplot(1, 2 if key else 1, 1)
    ax.hist(err, bins=max(5, min(40, int(np.sqrt(err.size)) * 2)), color="C0", alpha=0.8)
    ax.axvline(0.0, color="k", lw=0.8)
    ax.set_xlabel(f"error of {s.name} [{s.unit or '-'}]")
    ax.set_ylabel("runs")
    if key:
        ax2 = fig.add_subplot(1, 2, 2)
        x = [r["varied"].get(key) for r in used]
        e = [r["values"][s.name] - r["truth"][s.name] for r in used]
        ax2.plot(x, e, ".", color="C1")
        ax2.axhline(0.0, color="k", lw=0.8)
        ax2.set_xlabel(key)
        ax2.set_ylabel("error")
    fig.tight_layout()
    return _png(fig)


def write_html(results: list[dict[str, Any]], summary: list[MeasurementSummary], path: Path, title: str,
               counts: dict[str, int]) -> Path:
    """The campaign's HTML report: the summary table and its figures, one self-contained page."""
    esc = html.escape
    parts = [f"<!doctype html><html><head><meta charset='utf-8'><title>{esc(title)}</title>"
             "<style>body{font-family:sans-serif;margin:2em}td,th{padding:2px 8px;text-align:right}"
             "td:first-child,th:first-child{text-align:left}.no{color:#b00}</style></head><body>",
             f"<h1>{esc(title)}</h1>",
             "<p>" + ", ".join(f"{esc(k)}: {v}" for k, v in counts.items()) + "</p>",
             "<table><tr><th>measurement</th><th>unit</th><th>n</th><th>bias</th><th>&plusmn;95%</th><th>std</th>"
             "<th>std/CRLB</th><th>coverage</th><th>band</th></tr>"]
    for s in summary:
        band = "" if s.band_low is None else f"[{s.band_low:.3f}, {s.band_high:.3f}]"
        cov = "" if s.coverage is None else f"{s.coverage:.3f}"
        cls = " class='no'" if s.covered is False else ""
        parts.append(f"<tr><td>{esc(s.name)}</td><td>{esc(s.unit)}</td><td>{s.n}</td><td>{_g(s.bias)}</td>"
                     f"<td>{_g(s.bias_ci95)}</td><td>{_g(s.std)}</td><td>{_g(s.std_over_crlb, 3)}</td>"
                     f"<td{cls}>{cov}</td><td>{band}</td></tr>")
    parts.append("</table>")
    cover = _coverage_figure(summary)
    if cover:
        parts.append(f"<h2>Coverage against the binomial band</h2><img src='data:image/png;base64,{cover}'>")
    key = _varied_key(results)
    parts.append("<h2>Errors</h2>")
    for s in summary:
        png = _measurement_figure(results, s, key)
        if png:
            parts.append(f"<h3>{esc(s.name)}</h3><img src='data:image/png;base64,{png}'>")
    failed = [r for r in sorted(results, key=lambda r: r["index"]) if r["outcome"] in NOT_MEASURED]
    if failed:
        parts.append("<h2>Runs that did not measure</h2><ul>")
        parts += [f"<li>{esc(r['run_id'])}: {esc(r['outcome'])} {esc(r.get('error') or r.get('end_reason') or '')}"
                  "</li>" for r in failed]
        parts.append("</ul>")
    parts.append("</body></html>")
    path.write_text("\n".join(parts))
    return path
