"""A run's report: the figures its procedure names (matplotlib), laid out with its identity,
parameters and measurements by a Jinja2 template into one self-contained HTML page (figures as
inline SVG), and the same page as a PDF (WeasyPrint, the `pdf` extra) for the calibration file."""

from __future__ import annotations

import functools
import math
from pathlib import Path
from typing import Any

from bench.figures import ReportFigure, generic_figures
from bench.numbers import (
    DASH,
    error_in_intervals,
    limits,
    plain,
    pretty_unit,
    sig,
    truth_outside,
    truth_text,
    with_interval,
)
from bench.pdf import require_weasyprint, write_pdf
from bench.reporting.drawing import DrawnFigure

TEMPLATES = Path(__file__).with_name("templates")


def procedure_of(data: Any) -> Any | None:
    """The run's procedure, built with the run's parameters (None when it is not found or the
    recorded parameters no longer validate)."""
    from procedures import find_procedure

    try:
        return find_procedure(str(data.attrs.get("procedure", "")))(data.params)
    except Exception:  # noqa: BLE001 - an unknown or changed procedure still gets a report
        return None


def figures_for(data: Any, proc: Any = None) -> tuple[list[ReportFigure], list[str]]:
    """(figures, notes): the figures the procedure names through its `figures(data)` hook, else a
    plot of every stream; a hook that fails on this data leaves a note and the stream plots."""
    proc = proc if proc is not None else procedure_of(data)
    hook = getattr(proc, "figures", None)
    if hook is None:
        return generic_figures(data), []
    try:
        return list(hook(data)), []
    except Exception as exc:  # noqa: BLE001 - a figure that cannot be drawn must not lose the report
        why = f"{type(exc).__name__}: {exc}"
        return generic_figures(data), [f"the figures of {proc.name} could not be drawn from this run ({why}); "
                                       "the raw streams are plotted instead"]


def drawn_figures(data: Any, proc: Any = None, *, png: bool = False, workers: int = 1,
                  meanwhile: Any = None) -> tuple[list[DrawnFigure], list[str]]:
    """(figures drawn, notes): as figures_for, each figure drawn as SVG (and with png as the PDF's
    PNG); with workers > 1 built and drawn by that many processes at once (bench.reporting.drawing)
    from the procedure's `figure_parts()` hook, or else built here and drawn so.  meanwhile: as
    draw_parts."""
    from functools import partial

    from bench.reporting.drawing import draw_parts

    proc = proc if proc is not None else procedure_of(data)
    parts_hook = getattr(proc, "figure_parts", None)
    if parts_hook is not None:
        ran: list[bool] = []
        failed: list[BaseException] = []

        def guarded() -> None:
            ran.append(True)
            try:
                if meanwhile is not None:
                    meanwhile()
            except BaseException as exc:
                failed.append(exc)
                raise

        try:
            if workers > 1:
                data.read_streams()  # once, shared by the forked processes
            parts = [partial(part, data) for part in parts_hook()]
            return draw_parts(parts, png, workers=workers, meanwhile=guarded, in_child=data.reopen), []
        except Exception:  # noqa: BLE001 - figures_for says what failed and draws the streams instead
            if failed:  # meanwhile's own error (no PDF library), not a figure's
                raise
            meanwhile = None if ran else meanwhile  # done once only
    figs, notes = figures_for(data, proc)
    return draw_parts([partial(_one, f) for f in figs], png, workers=workers, meanwhile=meanwhile), notes


def _one(fig: ReportFigure) -> list[ReportFigure]:
    return [fig]


def _param_rows(data: Any, proc: Any) -> list[dict[str, str]]:
    specs = type(proc).param_specs() if proc is not None else {}
    rows = []
    for name, value in data.params.items():
        spec = specs.get(name)
        unit = getattr(spec, "unit", "") or ("1" if _is_number(value) else "")  # "": dimensionless, as declared
        rows.append({"name": name, "value": plain(value) if not isinstance(value, str) else value,
                     "unit": pretty_unit(unit), "doc": getattr(spec, "doc", "") or ""})
    return rows


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _measurement_rows(data: Any, row: dict[str, Any] | None) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """(the run's own measurements, the re-analyses `gyrobench analyze` stored) as table rows:
    two tables, so a re-fit never reads as part of what the run measured."""
    from procedures import measurement_periods, measurement_truth, no_interval_reasons, no_truth_reasons

    name = data.attrs.get("procedure")
    known = {
        "truth": measurement_truth(name, data.truth),  # by declaration, not by matching names
        "periods": measurement_periods(name),  # an axis angle's truth: its nearest image
        "lab": (data.attrs.get("lab_limits") or {}).get("measurements", {}),  # `gyrobench run --limits`' verdicts
        "why_not": no_interval_reasons(name),  # a value without an interval says why
        "why_no_truth": no_truth_reasons(name),  # and one compared with no truth (on a simulated station)
    }
    own: dict[str, dict[str, Any]] = {}
    for m in data.measurements():
        key = m["name"] if m.get("dut") is None else f"{m['dut']}:{m['name']}"
        own[key] = {**m, "name": key, "source": "run"}
    again: dict[str, dict[str, Any]] = {}
    for m in (row or {}).get("measurements", []):
        if m.get("source") == "analyze":
            key = m["name"] if m.get("dut") is None else f"{m['dut']}:{m['name']}"
            ci = [m.get("ci95_low"), m.get("ci95_high")]
            again[key] = {**m, "name": key, "ci95": ci if None not in ci else None, "base": m["name"]}
    return _table_rows(own, known), _table_rows(again, known)


def _table_rows(found: dict[str, dict[str, Any]], known: dict[str, Any]) -> list[dict[str, Any]]:
    """Table rows of measurements: value and interval by the digit rule, the row's own outcome, the
    truth and whether it lies outside the interval (an axis angle modulo its period)."""
    truth, periods, lab, why_not = known["truth"], known["periods"], known["lab"], known["why_not"]
    out = []
    for name, m in found.items():
        ci = m.get("ci95")
        value, interval = with_interval(m.get("value"), ci)
        base = m.get("base", name)
        t, period = truth.get(base), periods.get(base)
        verdict = lab.get(name) if m.get("source") == "run" else None
        outcome, lims = _row_outcome(m, verdict)
        why = why_not.get(base, "") if interval == DASH and m.get("outcome") != "NOT_MEASURED" else ""
        out.append({
            "name": name, "value": value, "interval": interval, "why": why, "unit": pretty_unit(m.get("unit") or "1"),
            "limits": lims, "outcome": outcome, "outcome_class": outcome.split(" ")[0],
            "truth": truth_text(t, ci) if t is not None else DASH,
            "truth_why": known["why_no_truth"].get(base, "") if t is None else "",
            "error": error_in_intervals(m.get("value"), t, ci, period) if t is not None else DASH,
            "outside": bool(t is not None and truth_outside(m.get("value"), t, ci, period)),
            "compared": t is not None and truth_outside(m.get("value"), t, ci, period) is not None,
        })
    return out


def _row_outcome(m: dict[str, Any], verdict: dict[str, Any] | None) -> tuple[str, str]:
    """(outcome, limits) of one row, its own status: the lab's verdict when a limit names it
    (MARGINAL: ILAC G8's conditional outcome), the procedure's own limits' outcome, else
    'measured' or NOT_MEASURED; never the run's outcome."""
    if verdict is not None:
        lim = verdict.get("limits") or {}
        outcome = verdict["outcome"] + (" (conditional)" if verdict["outcome"] == "MARGINAL" else "")
        return outcome, f"{limits(lim.get('low'), lim.get('high'))} ({verdict.get('rule')})"
    outcome = m.get("outcome") or DASH
    if outcome == "COMPLETE":  # no limit judged it: measured, nothing more
        outcome = "measured"
    return outcome, limits(m.get("low"), m.get("high"))


def _identity(data: Any, proc: Any) -> list[tuple[str, str]]:
    a = data.attrs
    duts = a.get("duts") or []
    station = a.get("station") or {}
    sim = station.get("simulation") or {}
    return [
        ("run id", str(a.get("run_id", DASH))),
        ("procedure", f"{a.get('procedure', DASH)}" + (f" — {type(proc).title()}" if proc is not None else "")),
        ("station", f"{a.get('station_id', DASH)}" + (" (simulated" + (f", preset {sim['preset']}" if sim.get("preset")
                                                                       else "") + ")" if a.get("simulated") else "")),
        ("DUT", ", ".join(map(str, duts)) if duts else DASH),
        ("operator", str(a.get("operator") or DASH)),
        ("software version", str(a.get("software_version") or DASH)),
        ("seed", str(a["seed"]) if a.get("seed") is not None else DASH),
        ("started", str(a.get("started_at") or DASH)),
        ("finished", str(a.get("finished_at") or DASH)),
        ("bench time", f"{sig(a.get('simulated_s'))} s" if a.get("simulated_s") is not None else DASH),
        ("wall time", f"{sig(a.get('wall_s'))} s" if a.get("wall_s") is not None else DASH),
    ]


def _log_rows(data: Any, limit: int = 200) -> list[tuple[str, str, str]]:
    rows = data.log()
    return [(f"{float(r.get('t_sim_s', math.nan)):.3f}", str(r.get("level", "")), str(r.get("msg", "")))
            for r in rows[-limit:]]


def context(data: Any, row: dict[str, Any] | None = None,
            figures: tuple[list[ReportFigure] | list[DrawnFigure], list[str]] | None = None,
            page: dict[str, Any] | None = None) -> dict[str, Any]:
    """Everything the template shows, as text (numbers already formatted); figures: the result
    of `figures_for(data)` when the caller already has it; page: `page_context(data, row)` likewise."""
    proc = procedure_of(data) if figures is None or not page else None
    figs, notes = figures if figures is not None else figures_for(data, proc)
    return {
        **(page or page_context(data, row, proc)),
        "figures": [{"title": f.title, "svg": f.svg(), "note": f.note, "key": f.key, "table": f.table} for f in figs],
        "notes": notes + list(getattr(data, "notes", [])),
    }


def page_context(data: Any, row: dict[str, Any] | None = None, proc: Any = None) -> dict[str, Any]:
    """What the template shows besides the figures and notes: the run's identity, parameters,
    measurements and log (proc: the run's procedure, when the caller has it)."""
    proc = proc if proc is not None else procedure_of(data)
    a = data.attrs
    rows, reanalysis = _measurement_rows(data, row)
    # the truth columns on a simulated station, when a measurement has a truth to compare with
    truth_shown = bool(a.get("simulated") and data.truth and any(r["truth"] != DASH for r in rows + reanalysis))
    compared = [r for r in rows if r["compared"]]
    lab = a.get("lab_limits")
    judged_any = bool(lab) or any(r["outcome"] in ("PASS", "FAIL", "MARGINAL") for r in rows)
    return {
        "run_id": a.get("run_id", data.path.stem),
        "procedure": a.get("procedure", ""),
        "outcome": a.get("outcome", "UNFINISHED"),
        "end_reason": a.get("end_reason", "the run did not finish (killed?)"),
        "safe_state": bool(a.get("safe_state")),
        "incomplete": data.incomplete,
        "identity": _identity(data, proc),
        "params": _param_rows(data, proc),
        "measurements": rows,
        "reanalysis": reanalysis,
        "truth_shown": truth_shown,
        # "7 of 16 truths outside their 95 % intervals", on a simulated station
        "truth_outside": (sum(r["outside"] for r in compared), len(compared)) if truth_shown and compared else None,
        "lab_limits": lab or None,
        "no_limits": not judged_any,
        "log": _log_rows(data),
    }


def render_html(data: Any, row: dict[str, Any] | None = None, ctx: dict[str, Any] | None = None, *,
                template: str = "report.html.j2", extra: dict[str, Any] | None = None) -> str:
    """The report page of one run (a RunData) and, when known, its results-store row.  template: a
    template in bench/reporting/templates that extends report.html.j2 and fills its `certificate`
    block (a page before the report); extra: the variables that template adds."""
    return _template(template).render(**(ctx or context(data, row)), **(extra or {}))


@functools.cache
def _environment(templates: Path) -> Any:
    import jinja2

    return jinja2.Environment(loader=jinja2.FileSystemLoader(templates), autoescape=True,
                              trim_blocks=True, lstrip_blocks=True, undefined=jinja2.StrictUndefined)


def _template(name: str) -> Any:
    """A template of TEMPLATES, compiled once a process (Jinja2 checks the file for changes)."""
    return _environment(TEMPLATES).get_template(name)


def write_report(raw_file: str | Path, row: dict[str, Any] | None = None, output: str | Path | None = None,
                 pdf: bool = False, *, template: str = "report.html.j2",
                 extra: dict[str, Any] | None = None, workers: int = 1) -> list[Path]:
    """Write the HTML report beside the raw file (or to output) and, with pdf, the PDF beside it;
    template and extra: as render_html (a page that extends the report, e.g. a certificate);
    workers: processes that build and draw the figures at once (drawn_figures)."""
    from bench.recorder import open_run

    if pdf and workers <= 1:
        require_weasyprint()  # a missing PDF library is said before anything is written
    with open_run(raw_file) as data:
        page: dict[str, Any] = {}

        def meanwhile() -> None:  # while the other processes draw: WeasyPrint (checked before writing), the page
            if pdf:
                require_weasyprint()
            page.update(page_context(data, row))
            _template(template)

        figures = drawn_figures(data, png=pdf, workers=workers, meanwhile=meanwhile)
        ctx = context(data, row, figures, page)
        html = render_html(data, row, ctx, template=template, extra=extra)
        out = Path(output or data.path.with_suffix(".html"))
        out.write_text(html, encoding="utf-8")
        paths = [out]
        if pdf:  # the same page with each figure, drawn once, as a PNG (WeasyPrint is slow on SVG)
            printed = render_html(data, row, with_png_figures(ctx, figures[0]), template=template, extra=extra)
            paths.append(write_pdf(printed, out.with_suffix(".pdf")))
    return paths


def with_png_figures(ctx: dict[str, Any], figs: list[ReportFigure] | list[DrawnFigure]) -> dict[str, Any]:
    """The page's context with each figure's inline SVG replaced by the same figure as an inline
    PNG (<img>, bench.figures.PRINT_DPI): what the PDF prints, ~30x faster for WeasyPrint to draw."""
    import base64

    from markupsafe import Markup

    shown = []
    for f, fig in zip(ctx["figures"], figs, strict=True):
        uri = "data:image/png;base64," + base64.b64encode(fig.png()).decode("ascii")
        shown.append({**f, "svg": Markup('<img class="figure" alt="{}" src="{}">').format(fig.title, uri)})
    return {**ctx, "figures": shown}
