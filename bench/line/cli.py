"""`gyrobench line run | simulate | report | export`: the production line's commands."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from . import LineError

EXIT_OK, EXIT_BAD, EXIT_USAGE = 0, 1, 2


def _context(args: argparse.Namespace, *, station_name: str, operator: str, db_url: str | None):
    from bench.results import ResultsStore

    from .db import LineDB
    from .limits import load_limits
    from .run import LineContext
    from .sequence import load_sequence

    seq = load_sequence(args.sequence)
    limits_name = args.limits or seq.limits
    if not limits_name:
        raise LineError(f"sequence {seq.name!r} names no limits file: give --limits FILE")
    limits = load_limits(limits_name)
    runs_dir = Path(args.runs_dir)
    runs_dir.mkdir(parents=True, exist_ok=True)
    url = db_url or str(runs_dir / "results.sqlite")
    store = ResultsStore(url, offline_ok=True, spool_dir=runs_dir / "spool")
    db = LineDB(url)
    return LineContext(seq, limits, station_name, operator, runs_dir, store=store, db=db, lot=args.lot or "")


def _station_of(args: argparse.Namespace, seq_station: str) -> str:
    name = args.station or seq_station
    if not name:
        raise LineError("no station: give --station NAME|FILE (the sequence names none)")
    return name


def check_steps(seq: Any, station: Any) -> None:
    """Every step's procedure fits the station (its device roles, the kind of gyro, the limits),
    before a unit is scanned; LineError names the step and why."""
    from bench.engine.demands import StationMismatch, check_station

    for i, step in enumerate(seq.steps, 1):
        proc = step.make()
        missing = [r for r in proc.requires if r not in station.config.devices]
        if missing:
            raise LineError(f"{seq.source}: [[step]] #{i} {step.procedure} needs device role(s) {missing}; "
                            f"station {station.id!r} has {sorted(station.config.devices)}")
        try:
            check_station(proc, station)
        except StationMismatch as exc:
            raise LineError(f"{seq.source}: [[step]] #{i} {step.procedure}: {exc}") from None


def cmd_run(args: argparse.Namespace) -> int:
    """One unit (scanned or --dut) through a sequence; its record(s); exit 0 on PASS."""
    from bench.composition import load_station

    from .prompts import make_operator, stdin_is_terminal
    from .sequence import load_sequence

    if not args.operator.strip():
        raise LineError("--operator NAME is required on a line (the record names who tested the unit)")
    if args.window:  # before anything opens: Qt without a display aborts the process
        from bench.gui.app import window_unavailable

        why = window_unavailable("line run --window")
        if why:
            raise LineError(why)
    seq = load_sequence(args.sequence)
    station_name = _station_of(args, seq.station)
    overrides = {} if args.seed is None else {"seed": args.seed}
    station = load_station(station_name, **overrides)  # the file checked before anything opens
    duts = args.dut or []
    faults = [_parse_slot_fault(f) for f in args.fault or []]
    if hasattr(station, "slots"):  # several gyros on one table: one unit a slot
        return _run_batch(args, seq, station, duts, faults)
    if args.window:
        raise LineError(f"--window shows a batch on a station with slots; station {station.id!r} holds one unit "
                        "(its window: gyrobench gui --operator)")
    if len(duts) > 1:
        raise LineError(f"station {station.id!r} holds one unit: give one --dut (or a station with [slots.N])")
    if any(slot is not None for _, _, slot in faults):
        raise LineError(f"station {station.id!r} has no slots: --fault KIND@SECONDS without :slotN")
    args.dut = duts[0] if duts else None
    check_steps(seq, station)
    if args.runs_dir is None:  # the station's folder and store, as `gyrobench run` uses them
        args.runs_dir = station.runs_dir
    db_url = args.db or (station.results_url if args.runs_dir == station.runs_dir else None)
    operator = make_operator(serial=args.dut, assume_yes=args.yes, interactive=stdin_is_terminal())
    serial = operator.scan_serial()
    ctx = _context(args, station_name=station.id, operator=args.operator, db_url=db_url)
    records = []
    try:
        from .run import run_unit

        if not operator.confirm(f"unit {serial} is in the fixture of station {station_name!r}?"):
            raise LineError(f"unit {serial}: the fixture was not confirmed; nothing was run")
        def open_station():
            st = load_station(station_name, **overrides)
            for kind, at_s, _ in faults:
                st.schedule_fault(kind, at_s)
            return st

        records = run_unit(ctx, open_station, serial, operator, first_attempt=ctx.db.next_attempt(serial))
    finally:
        ctx.store.close()
        ctx.db.close()
    _print_records(records, args.json)
    for r in records:
        if r.get("db_error"):
            print(f"gyrobench: {r['db_error']}", file=sys.stderr)
            return EXIT_BAD
    final = records[-1]["outcome"] if records else "ERROR"
    return EXIT_OK if final == "PASS" else EXIT_BAD


def _parse_slot_fault(text: str) -> tuple[str, float, int | None]:
    """`KIND@SECONDS` or `KIND@SECONDS:slotN` -> (kind, seconds, slot or None)."""
    from bench.fault_kinds import parse_fault

    head, sep, where = text.rpartition(":slot")
    slot = None
    if sep:
        if not where.isdigit() or int(where) < 1:
            raise LineError(f"--fault {text!r}: the slot after ':slot' is a number from 1 (e.g. link-drop@150:slot3)")
        slot, text = int(where), head
    try:
        kind, at_s = parse_fault(text)
    except ValueError as exc:
        raise LineError(str(exc)) from None
    return kind, at_s, slot


def _run_batch(args: argparse.Namespace, seq: Any, station: Any, duts: list[str], faults: list) -> int:
    """Several units at once on a several-gyros station: --dut in slot order (slot 1 first)."""
    from bench.engine.batch import BatchError, check_batchable
    from bench.slots import BATCH_ROLES
    from procedures import find_procedure

    from .batch_run import run_batch_attempt
    from .prompts import check_serial, make_operator, stdin_is_terminal

    if not duts:
        raise LineError(f"station {station.id!r} holds {station.n_slots} units: give one --dut SERIAL per slot "
                        "in slot order (slot 1 first)")
    if len(duts) > station.n_slots:
        raise LineError(f"{len(duts)} --dut given; station {station.id!r} has {station.n_slots} slots")
    serials = {n: check_serial(s) for n, s in enumerate(duts, 1)}
    if len(set(serials.values())) != len(serials):
        raise LineError(f"--dut {', '.join(duts)}: a serial is given twice")
    check_steps(seq, station.slot(1))
    for step in seq.steps:
        try:
            check_batchable(find_procedure(step.procedure), BATCH_ROLES)
        except BatchError as exc:
            raise LineError(f"{seq.source}: {exc}") from None
    for kind, at_s, slot in faults:
        station.schedule_fault(kind, at_s, slot)
    if args.runs_dir is None:
        args.runs_dir = station.runs_dir
    db_url = args.db or (station.results_url if args.runs_dir == station.runs_dir else None)
    operator = make_operator(serial=serials[1], assume_yes=args.yes, interactive=stdin_is_terminal())
    ctx = _context(args, station_name=station.id, operator=args.operator, db_url=db_url)
    records: list[dict[str, Any]] = []
    try:
        placed = ", ".join(f"{s} in slot {n}" for n, s in serials.items())
        if not operator.confirm(f"units {placed} are in the fixtures of station {station.id!r}?"):
            raise LineError("the fixtures were not confirmed; nothing was run")
        try:
            station.open()
        except Exception as exc:  # noqa: BLE001 - a station that does not open is one line
            raise LineError(f"station {station.id!r} did not open: {type(exc).__name__}: {exc}") from None
        try:
            attempts = {s: ctx.db.next_attempt(s) for s in serials.values()}
            if args.window:  # the batch in a worker thread, its columns in a window on this thread
                from bench.gui.batch_window import run_batch_in_window

                records = run_batch_in_window(
                    serials, lambda: run_batch_attempt(ctx, station, serials, operator, attempts), ctx,
                    close_when_done=args.close_when_done)
            else:
                records = run_batch_attempt(ctx, station, serials, operator, attempts)
        finally:
            station.close()
    finally:
        ctx.store.close()
        ctx.db.close()
    _print_records(records, args.json)
    if not args.json:
        counts = _counts(records)
        print(f"batch of {len(records)} units on {station.id}: " + ", ".join(f"{k} {v}" for k, v in counts.items()))
    if any(r.get("db_error") for r in records):
        return EXIT_BAD
    return EXIT_OK if records and all(r["outcome"] == "PASS" for r in records) else EXIT_BAD


def cmd_simulate(args: argparse.Namespace) -> int:
    """A simulated lot through a sequence, and the check of every outcome against the drawn truth."""
    from bench.station_config import load_config

    from .prompts import make_operator
    from .sequence import load_sequence
    from .simulate import check_lot, draw_lot, simulate_lot, undecided

    if args.units < 1:
        raise LineError(f"--units={args.units} is below the limit 1")
    seq = load_sequence(args.sequence)
    station_name = _station_of(args, seq.station)
    cfg = load_config(station_name)
    if cfg.simulation is None:
        raise LineError(f"--station {station_name}: a real station; `line simulate` needs a simulated one")
    preset = cfg.simulation["preset"]
    args.lot = args.lot or f"sim-{args.seed}"
    try:
        units = draw_lot(preset, args.units, args.seed, args.lot)
    except ValueError as exc:
        raise LineError(str(exc)) from None
    args.runs_dir = args.runs_dir or cfg.station["runs_dir"]
    args.db = args.db or (cfg.station["results"] if args.runs_dir == cfg.station["runs_dir"] else None)
    ctx = _context(args, station_name=cfg.id, operator=args.operator or "simulator", db_url=args.db)
    operator = make_operator(serial=None, assume_yes=True, interactive=False)
    if not args.json:
        operator.show_outcome = lambda serial, outcome, summary: print(f"{serial}: {outcome}  {summary}", flush=True)
    else:
        operator.show_outcome = lambda *a: None
    try:
        records = simulate_lot(ctx, cfg.source, units, args.seed, operator)
    finally:
        ctx.store.close()
        ctx.db.close()
    wrong = check_lot(records)
    counts = _counts(records)
    untruthed = undecided(records)
    if args.json:
        print(json.dumps({"lot": args.lot, "units": len(units), "attempts": len(records), "counts": counts,
                          "wrong": wrong, "undecided_by_truth": untruthed,
                          "records": [r["record_file"] for r in records]}))
    else:
        print(f"lot {args.lot}: {len(units)} units, {len(records)} attempts; final outcomes "
              + ", ".join(f"{k} {v}" for k, v in counts.items()))
        for w in wrong:
            print(f"  WRONG {w}")
        if untruthed:
            print(f"  decided by a measurement without a true value: {', '.join(untruthed)}")
        print("  every outcome is right for its drawn truth" if not wrong else f"  {len(wrong)} wrong outcome(s)")
    return EXIT_OK if not wrong else EXIT_BAD


def _counts(records: list[dict[str, Any]]) -> dict[str, int]:
    last: dict[str, dict] = {}
    for r in records:
        last[r["serial"]] = r
    out: dict[str, int] = {}
    for r in last.values():
        out[r["outcome"]] = out.get(r["outcome"], 0) + 1
    return dict(sorted(out.items()))


def cmd_report(args: argparse.Namespace) -> int:
    from .db import LineDB
    from .report import write_line_report

    args.runs_dir = args.runs_dir or "runs"
    url = args.db or str(Path(args.runs_dir) / "results.sqlite")
    db = LineDB(url)
    try:
        paths = write_line_report(db, lot=args.lot, output=args.output, pdf=args.pdf, runs_dir=args.runs_dir)
    finally:
        db.close()
    print("\n".join(str(p) for p in paths))
    return EXIT_OK


def cmd_export(args: argparse.Namespace) -> int:
    """A unit record (JSON file) in OpenHTF's test-record layout."""
    from .record import to_openhtf

    try:
        record = json.loads(Path(args.record).read_text())
    except (OSError, ValueError) as exc:
        raise LineError(f"{args.record}: not a readable unit record ({exc})") from None
    print(json.dumps(to_openhtf(record), indent=1))
    return EXIT_OK


def cmd_import(args: argparse.Namespace) -> int:
    """Unit records (JSON files) into the line database; those already there are left alone."""
    from .db import LineDB

    args.runs_dir = args.runs_dir or "runs"
    db = LineDB(args.db or str(Path(args.runs_dir) / "results.sqlite"))
    added = 0
    try:
        for f in args.records:
            try:
                record = json.loads(Path(f).read_text())
            except (OSError, ValueError) as exc:
                raise LineError(f"{f}: not a readable unit record ({exc})") from None
            if not db.has(record):
                record.pop("db_error", None)
                db.save(record)
                added += 1
    finally:
        db.close()
    print(f"imported {added} record(s); {len(args.records) - added} already in the line database")
    return EXIT_OK


def _print_records(records: list[dict[str, Any]], as_json: bool) -> None:
    if as_json:
        print(json.dumps(records))
        return
    for r in records:
        print(f"{r['serial']} attempt {r['attempt']}: {r['outcome']}  ({r['sequence']}, lot {r['lot'] or '-'})")
        for m in r["measurements"]:
            if not m["rule"]:
                continue
            iv = m["interval"]
            ivt = "" if iv is None else f" [{iv[0]:.6g}, {iv[1]:.6g}]" if None not in iv else f" {iv}"
            lim = m["limits"]
            v = "-" if m["value"] is None else f"{m['value']:.6g}"
            print(f"  {m['name']:<24} {v} {m['unit']}{ivt}  limits {lim['low']}..{lim['high']}  "
                  f"{m['outcome']} ({m['rule']})")
        print(f"  record {r['record_file']}")


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--db", default=None, help="line database (= results store) URL or SQLite file "
                   "(default: the station's results store, else RUNS_DIR/results.sqlite)")
    p.add_argument("--runs-dir", default=None, help="raw files, records (RUNS_DIR/line/LOT/) and spool "
                   "(default: the station's, runs)")


def add_line_subcommand(sub: Any) -> None:
    """The `line` command group of the gyrobench CLI."""
    line = sub.add_parser("line", help="production line: run a sequence on a unit, simulate a lot, report")
    lsub = line.add_subparsers(dest="line_command", required=True)

    run = lsub.add_parser("run", help="one unit through a sequence (records judged against product limits)")
    run.add_argument("sequence", help="a shipped sequence (eol-hrg, eol-mems, ...) or a TOML file")
    run.add_argument("--dut", action="append", default=None, metavar="SERIAL",
                     help="the unit's serial (else it is scanned); on a station with slots one per slot, slot 1 first")
    run.add_argument("--fault", action="append", default=None, metavar="KIND@SECONDS[:slotN]",
                     help="inject a station fault (simulated stations); :slotN aims it at one slot's device")
    run.add_argument("--operator", required=True, metavar="NAME")
    run.add_argument("--station", default=None, help="built-in station name or station TOML (default: the sequence's)")
    run.add_argument("--limits", default=None, help="product limits (shipped name or TOML; default: the sequence's)")
    run.add_argument("--lot", default="")
    run.add_argument("--yes", action="store_true", help="answer yes to the fixture and table-spin questions")
    run.add_argument("--seed", type=int, default=None, help="simulation seed (simulated stations)")
    run.add_argument("--json", action="store_true", help="print the records as JSON")
    run.add_argument("--window", action="store_true",
                     help="on a station with slots: show a column a slot (outcome, step, live E(t)) with Abort")
    run.add_argument("--close-when-done", action="store_true",
                     help="with --window: close it when the batch ends (else it stays until closed)")
    _common(run)
    run.set_defaults(func=cmd_run)

    sim = lsub.add_parser("simulate", help="a simulated lot drawn around the station's preset, checked against truth")
    sim.add_argument("--units", type=int, default=5)
    sim.add_argument("--seed", type=int, default=0)
    sim.add_argument("--sequence", default="ci-mems")
    sim.add_argument("--limits", default=None)
    sim.add_argument("--station", default=None)
    sim.add_argument("--lot", default="")
    sim.add_argument("--operator", default="simulator")
    sim.add_argument("--json", action="store_true")
    _common(sim)
    sim.set_defaults(func=cmd_simulate)

    rep = lsub.add_parser("report", help="yield, histograms with limits, Cp/Cpk, unit history, control charts")
    rep.add_argument("--lot", default=None)
    rep.add_argument("-o", "--output", default=None, help="HTML file (default: RUNS_DIR/line/report[-LOT].html)")
    rep.add_argument("--html", action="store_true", help="the HTML report (always written)")
    rep.add_argument("--pdf", action="store_true", help="the PDF too")
    _common(rep)
    rep.set_defaults(func=cmd_report)

    imp = lsub.add_parser("import", help="unit records (JSON) the line database did not take, into it")
    imp.add_argument("records", nargs="+")
    _common(imp)
    imp.set_defaults(func=cmd_import)

    exp = lsub.add_parser("export", help="a unit record in OpenHTF's JSON test-record layout")
    exp.add_argument("record", help="a unit record JSON file")
    exp.set_defaults(func=cmd_export)
