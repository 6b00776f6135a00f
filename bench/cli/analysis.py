"""`gyrobench analyze` and `gyrobench report`: re-fit a recorded run, or write its HTML/PDF report."""

from __future__ import annotations

import argparse
import json
from typing import Any

from .common import EXIT_BAD_OUTCOME, EXIT_OK, EXIT_USAGE, _err, _store, _write_report


def add_parser(sub) -> None:
    """Register `analyze` and `report`."""
    analyze = sub.add_parser(
        "analyze", help="re-fit a recorded run with its procedure's analysis hook; the results are stored as "
        "the run's re-analysis rows (kept apart from its own; a second analyze replaces them)")
    analyze.add_argument("run", help='run id, unique prefix, "last", or a raw .h5 file')
    analyze.add_argument("--results", default=None)
    analyze.add_argument("--json", action="store_true")
    analyze.add_argument("--procedure", default=None, help="analyse with another procedure (name or file)")
    analyze.add_argument("--no-store", action="store_true", help="print the re-fit only; store nothing")
    analyze.add_argument("--figures", default=None, metavar="DIR", help="also write the report's figures (SVG)")
    analyze.set_defaults(func=cmd_analyze)

    report = sub.add_parser("report", help="an HTML report with plots of a run")
    report.add_argument("run", help='run id, unique prefix, "last", or a raw .h5 file')
    report.add_argument("--results", default=None)
    report.add_argument("-o", "--output", default=None)
    report.add_argument("--pdf", action="store_true", help="the report as a PDF too, beside the HTML")
    report.add_argument("--against", default=None, metavar="RUN",
                        help="a thermal-ramp and a thermal-soak of the same unit (either way round): the ramp's "
                        "report with the two methods' residuals compared first, written as RAMP-vs-SOAK.html")
    report.set_defaults(func=cmd_report)


def cmd_analyze(args: argparse.Namespace) -> int:
    from procedures import ProcedureNotFound, find_procedure

    opened = _open_for_command(args)
    if isinstance(opened, int):
        return opened
    data, store, run_id = opened
    with data:
        if not (args.procedure or data.attrs.get("procedure")):
            _err(f"{data.path}: the file does not name its procedure: give --procedure NAME")
            return EXIT_USAGE
        try:
            cls = find_procedure(args.procedure or data.attrs["procedure"])
        except ProcedureNotFound as exc:
            _err(str(exc))
            return EXIT_USAGE
        proc = cls(data.params)
        if not cls.has_analysis():
            _err(f"procedure {cls.name!r} has no analysis hook; nothing to re-fit")
            return EXIT_USAGE
        incomplete = data.incomplete
        try:
            results = [proc.resolve_result(r) for r in proc.analysis(data)]  # declared names, units
        except Exception as exc:  # noqa: BLE001 - a hook on data it cannot use: one message, no traceback
            why = f"{exc}" if isinstance(exc, (KeyError, ValueError)) else f"{type(exc).__name__}: {exc}"
            if incomplete and incomplete not in why:
                why += f" (incomplete run: {incomplete})"
            _err(f"cannot analyse run {run_id} with {cls.name!r}: {why}")
            return EXIT_BAD_OUTCOME
        figures = _write_figures(data, proc, args.figures) if args.figures else []
        notes = list(data.notes)
        truth = data.truth or {}
    stored = None
    if store is not None and not args.no_store:
        store.save_analysis(run_id, results)
        stored = store.display_url
    out = {r.name if r.dut is None else f"{r.dut}:{r.name}": r.as_json() for r in results}
    if args.json:
        print(json.dumps({"run_id": run_id, "measurements": out, "truth": truth or None, "incomplete": incomplete,
                          "notes": notes, "figures": [str(p) for p in figures], "stored_in": stored}))
    else:
        print(f"re-analysis of run {run_id} ({cls.name})")
        if incomplete:
            print(f"  from an INCOMPLETE run: {incomplete}")
        for note in notes:
            print(f"  note: {note}")
        declared_truth = cls.truth_for(truth)
        for name, m in out.items():
            t = f"  truth {declared_truth[name]:.6g}" if name in declared_truth else ""
            print(f"  {name} = {m['value']} {m['unit']}  ci95 {m['ci95']}  {m['outcome']}{t}")
        for path in figures:
            print(f"  figure {path}")
        if stored:
            print(f"  stored in {stored} as this run's re-analysis ({len(results)} row(s), replacing any earlier "
                  "one; the run's own results are kept apart; --no-store stores nothing)")
        else:
            print("  not stored" + (" (a raw file, no store)" if store is None else " (--no-store)"))
    return EXIT_OK


def cmd_report(args: argparse.Namespace) -> int:
    if args.against:
        return _report_against(args)
    opened = _open_for_command(args)
    if isinstance(opened, int):
        return opened
    data, store, run_id = opened
    with data:
        row = store.get_run(run_id) if store is not None else None
        raw_file = str(data.path)
    paths = _write_report(raw_file, row, args.output, pdf=args.pdf)
    print("\n".join(str(p) for p in paths))
    return EXIT_USAGE if args.pdf and len(paths) < 2 else EXIT_OK


def _report_against(args: argparse.Namespace) -> int:
    """`report RUN --against OTHER`: the thermal comparison page, or one line why not."""
    from bench.pdf import PdfUnavailable
    from bench.reporting.thermal_compare import CompareRefused, write_comparison

    files, rows = [], {}
    for run in (args.run, args.against):
        opened = _open_for_command(argparse.Namespace(run=run, results=args.results))
        if isinstance(opened, int):
            return opened
        data, store, run_id = opened
        with data:
            files.append(str(data.path))
            rows[str(run_id)] = store.get_run(run_id) if store is not None else None
    pdf = args.pdf
    try:
        try:
            paths = write_comparison(files[0], files[1], rows, args.output, pdf=pdf)
        except PdfUnavailable as exc:  # said before anything is written: the HTML alone, and why
            _err(str(exc))
            paths = write_comparison(files[0], files[1], rows, args.output)
    except CompareRefused as exc:
        _err(str(exc))
        return EXIT_USAGE
    except (KeyError, ValueError, RuntimeError) as exc:  # a run whose data the fits cannot use
        _err(f"cannot compare runs {args.run} and {args.against}: {exc}")
        return EXIT_BAD_OUTCOME
    print("\n".join(str(p) for p in paths))
    return EXIT_USAGE if pdf and len(paths) < 2 else EXIT_OK


def _open_recorded(run: str, results: str | None):
    """(RunData, store or None, run_id) from a run id / prefix / "last" or an .h5 path."""
    from pathlib import Path

    from bench.recorder import open_run

    if run.endswith(".h5") and Path(run).is_file():
        data = open_run(run)
        return data, None, data.attrs.get("run_id", Path(run).stem)
    store = _store(results)
    row = store.get_run(run)
    if not row["raw_file"] or not Path(row["raw_file"]).is_file():
        raise KeyError(f"run {row['run_id']}: raw file {row['raw_file']!r} is missing")
    return open_run(row["raw_file"]), store, row["run_id"]


def _open_for_command(args: argparse.Namespace) -> tuple[Any, Any, str] | int:
    """`_open_recorded` for analyze and report: (data, store, run id), or the exit code after one
    message (an unknown run or missing file: usage; a file that is not HDF5 or is damaged)."""
    from bench.recorder import NotARunFile

    try:
        return _open_recorded(args.run, args.results)
    except KeyError as exc:
        _err(str(exc.args[0]))
        return EXIT_USAGE
    except NotARunFile as exc:  # HDF5 from another program, or attributes we cannot read
        _err(str(exc))
        return EXIT_USAGE
    except OSError as exc:  # not an HDF5 file, or damaged
        _err(f"cannot read the raw file of {args.run!r}: {exc}")
        return EXIT_BAD_OUTCOME


def _write_figures(data, proc, directory: str) -> list:
    """The figures the report draws for this run, as SVG files in directory; their paths."""
    from pathlib import Path

    from bench.reporting import figures_for

    Path(directory).mkdir(parents=True, exist_ok=True)
    figs, notes = figures_for(data, proc)
    data.notes.extend(notes)
    return [f.save(directory) for f in figs]
