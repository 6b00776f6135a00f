"""`gyrobench line run | simulate | golden | unlock | report | import | verify | keygen | export`: the
production line's commands (exit codes, routing, calibration and the golden unit: docs/line.md)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from bench.validation import range_text

from . import LineError
from .checks import check_limits_measured, check_steps

EXIT_OK, EXIT_BAD, EXIT_USAGE = 0, 1, 2
#: `line run`'s exit code by the unit's final outcome (docs/line.md); a batch exits by its worst unit
EXIT_PASS, EXIT_FAIL, EXIT_MARGINAL, EXIT_ERROR, EXIT_ABORTED, EXIT_NOT_SAVED = 0, 1, 3, 4, 5, 6
OUTCOME_EXIT = {"PASS": EXIT_PASS, "FAIL": EXIT_FAIL, "MARGINAL": EXIT_MARGINAL, "ERROR": EXIT_ERROR,
                "ABORTED": EXIT_ABORTED}


def exit_code(records: list[dict[str, Any]]) -> int:
    """The exit code of a `line run`: its units' worst final outcome (PASS 0, FAIL 1, MARGINAL 3,
    ERROR 4, ABORTED 5); all PASS but a record the line database did not take: 6."""
    from .verdict import worst

    last: dict[str, dict[str, Any]] = {}
    for r in records:
        last[r["serial"]] = r
    if not last:
        return EXIT_ERROR
    code = OUTCOME_EXIT.get(worst(r["outcome"] for r in last.values()), EXIT_ERROR)
    if code == EXIT_PASS and any(r.get("db_error") for r in records):
        return EXIT_NOT_SAVED
    return code


def _context(args: argparse.Namespace, *, station_name: str, operator: str, db_url: str | None,
             config: Any = None):
    from bench.results import ResultsStore

    from .db import LineDB
    from .run import LineContext
    from .sequence import load_sequence

    seq = load_sequence(args.sequence)
    limits = _limits_of(args, seq)
    runs_dir = Path(args.runs_dir)
    runs_dir.mkdir(parents=True, exist_ok=True)
    url = db_url or str(runs_dir / "results.sqlite")
    store = ResultsStore(url, offline_ok=True, spool_dir=runs_dir / "spool")
    db = LineDB(url)
    from .integrity import station_signer

    signer = station_signer(config) if config is not None else None
    return LineContext(seq, limits, station_name, operator, runs_dir, store=store, db=db, lot=args.lot or "",
                       signer=signer)


def _limits_of(args: argparse.Namespace, seq: Any):
    """The product limits of a command: --limits, else the sequence's."""
    from .limits import load_limits

    limits_name = args.limits or seq.limits
    if not limits_name:
        raise LineError(f"sequence {seq.name!r} names no limits file: give --limits FILE")
    return load_limits(limits_name)


def check_inputs(args: argparse.Namespace, limits: Any, station_id: str) -> list[str]:
    """Operator, lot, station id and serials (--dut) checked against the product's formats and
    length limits before anything runs (bench/line/inputs.py); the serials, normalised."""
    from .inputs import check_lot, check_operator, check_reason, check_rework, check_serial, check_text

    if getattr(args, "rework", None) is not None:
        args.rework = check_rework(args.rework)
    if getattr(args, "retest_reason", None) is not None:
        args.retest_reason = check_reason(args.retest_reason)
    args.operator = check_operator(args.operator)
    args.lot = check_lot(args.lot or "", limits.lot_format)
    check_text("station", station_id)
    return [check_serial(d, limits.serial_format) for d in getattr(args, "dut", None) or []]


def check_station_ready(station: Any, runs_dir: str | None, *, lock_too: bool = True) -> None:
    """A station past a calibration due date, or locked by its golden unit, refuses line runs
    (bench/line/station_state.py); LineError says which and since when."""
    from .station_state import refusal

    why = refusal(station.config.calibration, runs_dir or station.runs_dir, station.id, lock_too=lock_too)
    if why:
        raise LineError(why)


def _station_of(args: argparse.Namespace, seq_station: str) -> str:
    name = args.station or seq_station
    if not name:
        raise LineError("no station: give --station NAME|FILE (the sequence names none)")
    return name


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
    limits = _limits_of(args, seq)
    station_name = _station_of(args, seq.station)
    overrides = {} if args.seed is None else {"seed": args.seed}
    station = load_station(station_name, **overrides)  # the file checked before anything opens
    duts = check_inputs(args, limits, station.id)
    check_station_ready(station, args.runs_dir)
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
    check_limits_measured(seq, limits)
    if args.runs_dir is None:  # the station's folder and store, as `gyrobench run` uses them
        args.runs_dir = station.runs_dir
    db_url = args.db or (station.results_url if args.runs_dir == station.runs_dir else None)
    operator = make_operator(serial=args.dut, assume_yes=args.yes, interactive=stdin_is_terminal(),
                             serial_format=limits.serial_format)
    ctx = _context(args, station_name=station.id, operator=args.operator, db_url=db_url, config=station.config)
    records = []
    try:
        from .routing import history, route
        from .run import run_unit

        serial = operator.scan_serial()
        ctx.routing[serial], tries = route(history(ctx.db, ctx.runs_dir, serial), serial, seq, rework=args.rework,
                                           retest_reason=args.retest_reason)
        if not operator.confirm(f"unit {serial} is in the fixture of station {station_name!r}?"):
            raise LineError(f"unit {serial}: the fixture was not confirmed; nothing was run")
        def open_station():
            st = load_station(station_name, **overrides)
            for kind, at_s, _ in faults:
                st.schedule_fault(kind, at_s)
            return st

        records = run_unit(ctx, open_station, serial, operator, max_tries=tries)
    finally:
        ctx.store.close()
        ctx.db.close()
    _print_records(records, args.json)
    for r in records:
        if r.get("db_error"):
            print(f"gyrobench: {r['db_error']}", file=sys.stderr)
    return exit_code(records)


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
    from .batch_run import check_batch_sequence, run_batch_units
    from .prompts import make_operator, stdin_is_terminal

    if not duts:
        raise LineError(f"station {station.id!r} holds {station.n_slots} units: give one --dut SERIAL per slot "
                        "in slot order (slot 1 first)")
    if len(duts) > station.n_slots:
        raise LineError(f"{len(duts)} --dut given; station {station.id!r} has {station.n_slots} slots")
    serials = dict(enumerate(duts, 1))  # checked by check_inputs
    if len(set(serials.values())) != len(serials):
        raise LineError(f"--dut {', '.join(duts)}: a serial is given twice")
    check_batch_sequence(seq, _limits_of(args, seq), station)
    for kind, at_s, slot in faults:
        station.schedule_fault(kind, at_s, slot)
    if args.runs_dir is None:
        args.runs_dir = station.runs_dir
    db_url = args.db or (station.results_url if args.runs_dir == station.runs_dir else None)
    operator = make_operator(serial=serials[1], assume_yes=args.yes, interactive=stdin_is_terminal())
    ctx = _context(args, station_name=station.id, operator=args.operator, db_url=db_url, config=station.config)
    records: list[dict[str, Any]] = []
    try:
        run = None
        if args.window:  # the batch in a worker thread, its columns in a window on this thread
            from bench.gui.batch_window import run_batch_in_window

            def run(work):
                return run_batch_in_window(serials, work, ctx, close_when_done=args.close_when_done)

        records = run_batch_units(ctx, station, serials, operator, rework=args.rework,
                                  retest_reason=args.retest_reason, run=run)
    finally:
        ctx.store.close()
        ctx.db.close()
    _print_records(records, args.json)
    if not args.json:
        counts = _counts(records)
        print(f"batch of {len(records)} units on {station.id}: " + ", ".join(f"{k} {v}" for k, v in counts.items()))
    for r in records:
        if r.get("db_error"):
            print(f"gyrobench: {r['db_error']}", file=sys.stderr)
    return exit_code(records)


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
    check_inputs(args, _limits_of(args, seq), cfg.id)
    try:
        units = draw_lot(preset, args.units, args.seed, args.lot)
    except ValueError as exc:
        raise LineError(str(exc)) from None
    args.runs_dir = args.runs_dir or cfg.station["runs_dir"]
    args.db = args.db or (cfg.station["results"] if args.runs_dir == cfg.station["runs_dir"] else None)
    from .station_state import refusal

    why = refusal(cfg.calibration, args.runs_dir, cfg.id)
    if why:
        raise LineError(why)
    check_limits_measured(seq, _limits_of(args, seq))
    ctx = _context(args, station_name=cfg.id, operator=args.operator or "simulator", db_url=args.db, config=cfg)
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


def cmd_golden(args: argparse.Namespace) -> int:
    """The golden unit through a sequence at shift start: each reference's drift recorded; a drift
    past its limit locks the station for line runs (exit 1), else exit 0."""
    import dataclasses

    from bench.composition import load_station

    from .golden import drifts, load_golden, lock_reason
    from .prompts import make_operator
    from .run import run_unit
    from .sequence import load_sequence
    from .station_state import append_log, lock

    golden = load_golden(args.golden)
    seq = load_sequence(args.sequence)
    seq = dataclasses.replace(seq, write_trims=False, max_attempts=1)  # a golden unit keeps its own trims
    limits = _limits_of(args, seq)
    station_name = _station_of(args, seq.station)
    overrides = {} if args.seed is None else {"seed": args.seed}
    station = load_station(station_name, **overrides)
    args.lot = args.lot or "golden"
    check_inputs(args, limits, station.id)
    check_station_ready(station, args.runs_dir, lock_too=False)  # a locked station may run its golden unit
    if args.runs_dir is None:
        args.runs_dir = station.runs_dir
    db_url = args.db or (station.results_url if args.runs_dir == station.runs_dir else None)
    ctx = _context(args, station_name=station.id, operator=args.operator, db_url=db_url, config=station.config)
    ctx.sequence = seq
    operator = make_operator(serial=golden.serial, assume_yes=True, interactive=False)
    if args.json:
        operator.show_outcome = lambda *a: None
    ctx.routing[golden.serial] = {"golden": golden.source, "retest_reason": "golden unit, daily check"}
    try:
        records = run_unit(ctx, lambda: load_station(station_name, **overrides), golden.serial, operator, max_tries=1)
    finally:
        ctx.store.close()
        ctx.db.close()
    rec = records[-1]
    rows = drifts(rec, golden)
    reason = lock_reason(golden.serial, rows)
    append_log(args.runs_dir, station.id, {"event": "golden", "serial": golden.serial, "golden_file": golden.source,
                                           "record_file": rec.get("record_file"), "outcome": rec["outcome"],
                                           "operator": args.operator, "drifts": rows, "held": reason is None})
    if reason:
        lock(args.runs_dir, station.id, reason, golden_record=rec.get("record_file"))
    if args.json:
        print(json.dumps({"serial": golden.serial, "record": rec.get("record_file"), "drifts": rows,
                          "locked": reason}))
    else:
        print(f"golden unit {golden.serial} on {station.id}: record {rec.get('record_file')}")
        for r in rows:
            drift = "not measured" if r["drift"] is None else f"drift {r['drift']:+.4g} {r['unit']}".rstrip()
            print(f"  {r['name']:<24} {drift} (limit ±{r['limit']:g})  {'ok' if r['ok'] else 'PAST LIMIT'}")
        print(f"station {station.id} LOCKED for line runs: {reason}" if reason else "drift within limits")
    return EXIT_BAD if reason else EXIT_OK


def cmd_unlock(args: argparse.Namespace) -> int:
    """Unlock a station its golden unit locked, with the reason logged."""
    from bench.station_config import load_config

    from .inputs import check_operator, check_reason
    from .station_state import unlock

    cfg = load_config(args.station)
    runs_dir = args.runs_dir or cfg.station["runs_dir"]
    held = unlock(runs_dir, cfg.id, check_reason(args.reason), check_operator(args.operator))
    print(f"station {cfg.id} unlocked ({args.reason}); it was locked since {held['at']}: {held['reason']}")
    return EXIT_OK


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


def _trusted(args: argparse.Namespace) -> set[str] | None:
    from .integrity import load_public_key

    return {load_public_key(k) for k in args.key} if args.key else None


def import_problems(record: dict[str, Any], db: Any, runs_dir: str, trusted: set[str] | None,
                    allow_unsigned: bool) -> list[str]:
    """Why a record may not enter the line database (empty: it may): its hash and signature, its
    raw files re-hashed, its verdicts judged again against its limits file, its chain."""
    from .integrity import raw_file_problems, rejudge_problems, signature_problem
    from .verify import _Predecessors, chain_problem

    sig = signature_problem(record, trusted)
    if sig and not (allow_unsigned and "not signed" in sig):
        return [sig]
    problems = raw_file_problems(record) + rejudge_problems(record)
    chain = chain_problem(record, _Predecessors(db, runs_dir))
    if chain and "is missing" not in chain:  # a predecessor not imported yet is no reason to refuse
        problems.append(chain)
    return problems


def cmd_import(args: argparse.Namespace) -> int:
    """Unit records (JSON files) into the line database, each checked first (import_problems);
    those already there are left alone, those that do not verify are refused (exit 1)."""
    from .db import LineDB

    args.runs_dir = args.runs_dir or "runs"
    trusted = _trusted(args)
    db = LineDB(args.db or str(Path(args.runs_dir) / "results.sqlite"))
    added, there, refused = 0, 0, []
    try:
        for f in args.records:
            try:
                record = json.loads(Path(f).read_text())
                if not isinstance(record, dict) or "serial" not in record or "started_at" not in record:
                    raise ValueError("not a unit record")
            except (OSError, ValueError) as exc:
                raise LineError(f"{f}: not a readable unit record ({exc})") from None
            record.pop("db_error", None)
            problems = import_problems(record, db, args.runs_dir, trusted, args.allow_unsigned)
            if problems:
                refused.append(f"{f}: refused: " + "; ".join(problems))
                continue
            row = db.find(record)
            try:
                if row is not None and row["outcome"] not in ("RUNNING", "INTERRUPTED"):
                    there += 1
                    continue
                if row is not None:  # its attempt row began and was left open: it gets its record
                    db.finish_attempt(row["id"], record)
                else:
                    db.save(record)
                added += 1
            except LineError as exc:
                refused.append(f"{f}: refused: {exc}")
    finally:
        db.close()
    for line in refused:
        print(f"gyrobench: {line}", file=sys.stderr)
    print(f"imported {added} record(s); {there} already in the line database"
          + (f"; {len(refused)} refused" if refused else ""))
    return EXIT_BAD if refused else EXIT_OK


def cmd_verify(args: argparse.Namespace) -> int:
    """A lot's records: hashes, signatures, raw files and each station's chain; the first break named."""
    from .db import LineDB
    from .inputs import check_lot
    from .verify import verify_lot

    lot = check_lot(args.lot) or ""
    args.runs_dir = args.runs_dir or "runs"
    trusted = _trusted(args)
    url = args.db or str(Path(args.runs_dir) / "results.sqlite")
    db = LineDB(url)
    try:
        v = verify_lot(db, args.runs_dir, lot, trusted)
    finally:
        db.close()
    if v.records == 0 and not v.breaks:
        raise LineError(f"lot {lot or '(none)'}: no records in {Path(args.runs_dir) / 'line'} or {url}")
    head = f"lot {lot or '(none)'}: {v.records} record(s) from {len(v.stations)} station(s)"
    if v.breaks:
        print(f"{head}: BROKEN; first break: {v.breaks[0]}")
        for b in v.breaks[1:]:
            print(f"  also: {b}")
    else:
        print(f"{head}: chain, signatures and raw files hold")
    for n in v.notes:
        print(f"  note: {n}")
    return EXIT_BAD if v.breaks else EXIT_OK


def cmd_keygen(args: argparse.Namespace) -> int:
    """A station's Ed25519 key pair: the private key (0600) and PATH.pub to give `verify --key`."""
    from .integrity import Signer, generate_key

    key, pub = generate_key(args.path)
    print(f"private key {key} (name it in the station file: [station] line_key = \"{key}\"; keep it out of "
          f"the repository)\npublic key  {pub} (key id {Signer(key).key_id}; give it to `line verify --key`)")
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
            bounds = range_text(lim["low"], lim["high"], m["unit"]) or "none"
            print(f"  {m['name']:<24} {v} {m['unit']}{ivt}  limits {bounds}  "
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
    run.add_argument("--rework", default=None, metavar="CODE",
                     help="the rework done to a unit that FAILED (needed to test it again)")
    run.add_argument("--retest-reason", default=None, metavar="TEXT",
                     help="why a unit that PASSED is tested again (needed to test it again)")
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

    gold = lsub.add_parser("golden", help="the golden unit at shift start: drift from its references; past a limit "
                           "the station locks")
    gold.add_argument("sequence", help="a shipped sequence or a TOML file")
    gold.add_argument("--golden", required=True,
                      help="golden file (TOML: [golden] serial, [reference.NAME] value, limit)")
    gold.add_argument("--operator", required=True, metavar="NAME")
    gold.add_argument("--station", default=None)
    gold.add_argument("--limits", default=None)
    gold.add_argument("--lot", default="")
    gold.add_argument("--seed", type=int, default=None)
    gold.add_argument("--json", action="store_true")
    _common(gold)
    gold.set_defaults(func=cmd_golden)

    unl = lsub.add_parser("unlock", help="unlock a station its golden unit locked (the reason is logged)")
    unl.add_argument("--station", required=True)
    unl.add_argument("--reason", required=True, metavar="TEXT")
    unl.add_argument("--operator", required=True, metavar="NAME")
    _common(unl)
    unl.set_defaults(func=cmd_unlock)

    rep = lsub.add_parser("report", help="yield, histograms with limits, Cp/Cpk, unit history, control charts")
    rep.add_argument("--lot", default=None)
    rep.add_argument("-o", "--output", default=None, help="HTML file (default: RUNS_DIR/line/report[-LOT].html)")
    rep.add_argument("--html", action="store_true", help="the HTML report (always written)")
    rep.add_argument("--pdf", action="store_true", help="the PDF too")
    _common(rep)
    rep.set_defaults(func=cmd_report)

    imp = lsub.add_parser("import", help="unit records (JSON) the line database did not take, into it")
    imp.add_argument("records", nargs="+")
    imp.add_argument("--key", action="append", default=None, metavar="PUB.pem",
                     help="a station's public key: only records signed by these keys are taken")
    imp.add_argument("--allow-unsigned", action="store_true",
                     help="take records of a station without a line_key (hash, chain, raw files and limits checked)")
    _common(imp)
    imp.set_defaults(func=cmd_import)

    ver = lsub.add_parser("verify", help="a lot's records: hashes, signatures, raw files and chains; the first break")
    ver.add_argument("lot")
    ver.add_argument("--key", action="append", default=None, metavar="PUB.pem",
                     help="a station's public key: records signed by any other key are breaks")
    _common(ver)
    ver.set_defaults(func=cmd_verify)

    key = lsub.add_parser("keygen", help="a station's Ed25519 key pair for signing unit records")
    key.add_argument("path", help="the private key file to create (PATH.pub beside it)")
    key.set_defaults(func=cmd_keygen)

    exp = lsub.add_parser("export", help="a unit record in OpenHTF's JSON test-record layout")
    exp.add_argument("record", help="a unit record JSON file")
    exp.set_defaults(func=cmd_export)
