"""`gyrobench run`: one procedure on one station, its record printed (or as JSON) and stored."""

from __future__ import annotations

import argparse
import json
import signal
import sys
from typing import Any

from .common import (
    BAD_OUTCOMES,
    EXIT_BAD_OUTCOME,
    EXIT_OK,
    EXIT_USAGE,
    StoreOpening,
    _check_runs_dir,
    _err,
    _speed,
    _write_report,
    exit_for_signal,
)


def add_parser(sub) -> None:
    """Register `run` and its options."""
    run = sub.add_parser("run", help="run a procedure (a registered name or a .py file) on a station")
    run.add_argument("procedure", help="a registered name, or a .py file (imported within 30 s, "
                                        "$GYROBENCH_IMPORT_TIMEOUT_S)")
    run.add_argument("--station", default="sim-hrg", help="built-in station name or a station TOML file")
    run.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help="a procedure parameter")
    run.add_argument("--seed", type=int, default=None, help="simulation seed (simulated stations)")
    run.add_argument("--speed", type=float, default=None, help="0 = lockstep (default), else x real time")
    run.add_argument("--json", action="store_true", help="print one JSON object with the result")
    run.add_argument("--fault", action="append", default=[], metavar="KIND@SECONDS", help="inject a fault")
    run.add_argument("--results", default=None, help="results store URL or SQLite file (default: station's)")
    run.add_argument("--runs-dir", default=None, help="directory of the raw HDF5 files (default: station's)")
    run.add_argument("--operator", default="")
    run.add_argument("--dut", action="append", default=[], metavar="SERIAL", help="serial of a gyro under test")
    run.add_argument("--limits", default=None, metavar="FILE",
                     help="the lab's limits (the line's limits format, ILAC G8 rules): a verdict per measurement")
    run.add_argument("--report", action="store_true", help="also write the run's HTML report and print its path")
    run.add_argument("--pdf", action="store_true", help="with --report: the report as a PDF too")
    run.set_defaults(func=cmd)


def _parse_sets(items: list[str]) -> dict[str, str]:
    """`--set NAME=VALUE` items by name, the values as typed (Param.convert parses them)."""
    from bench.validation import parse_assignment

    return dict(parse_assignment(item) for item in items)


def _check_people(args: argparse.Namespace) -> None:
    """--operator and each --dut checked for length and control characters (bench.validation)."""
    from bench.validation import check_label

    check_label("--operator", args.operator, allow_empty=True)
    for serial in args.dut:
        check_label("--dut", serial)


def _warn_unfired_faults(station: Any, faults: list[tuple[str, float]]) -> None:
    """A --fault whose time the run never reached did not test anything: say so."""
    sched = getattr(station, "faults", None)
    if sched is None or not faults:
        return
    end_s = float(getattr(station.world, "t_s", 0.0))
    for at_s, kind in list(sched.pending):
        _err(f"warning: fault {kind}@{at_s:g} s never fired: the run ended at {end_s:.1f} s")


def cmd(args: argparse.Namespace) -> int:
    from bench.composition import load_station
    from bench.composition.sim_station import SimStation
    from bench.devices import StationError
    from bench.engine import ParamError, Runner, check_station
    from bench.fault_kinds import parse_fault
    from bench.line import LineError
    from bench.results.lengths import check_inputs  # no SQLAlchemy: the store opens on its thread
    from procedures import ProcedureNotFound, find_procedure

    from .record_table import apply_limits, load_lab_limits, print_record

    try:
        _check_people(args)  # a serial's or operator's length and characters, before the procedure file is imported
        check_inputs(args.operator, args.dut)  # and what the results store keeps (the looser bound)
        proc_cls = find_procedure(args.procedure)
        params = _parse_sets(args.set)
        proc = proc_cls(params)  # parameters are checked here, before any device exists
        lab_limits = load_lab_limits(args.limits)  # a bad limits file is said before anything moves
        overrides: dict[str, Any] = {}
        if args.seed is not None:
            overrides["seed"] = args.seed
        if args.speed is not None:
            overrides["speed"] = _speed(args.speed)
        faults = [parse_fault(f) for f in args.fault]
        station = load_station(args.station, **overrides)
        if hasattr(station, "slots"):  # several gyros on one table: a batch, one unit a slot
            raise StationError(
                f"station {station.id!r} holds {station.n_slots} gyros on one table: run a sequence on them "
                f"together with `gyrobench line run SEQUENCE --station {args.station} --dut S1 --dut S2 ...`")
        missing = [r for r in proc_cls.requires if r not in station.config.devices]
        if missing:
            raise StationError(
                f"procedure {proc_cls.name!r} needs device role(s) {missing}; station "
                f"{station.id!r} has {sorted(station.config.devices)}"
            )
        check_station(proc, station)  # the kind of gyro and the station's limits, before anything opens
        if faults and not isinstance(station, SimStation):
            raise StationError(f"--fault needs a simulated station; {args.station!r} is real")
    except (ProcedureNotFound, ParamError, StationError, ValueError, LineError) as exc:
        _err(str(exc))
        return EXIT_USAGE
    _check_runs_dir(args.runs_dir or station.runs_dir)
    # a store that is down now still takes the run's record later, through the spool; opened while
    # the station opens (issue 36), and waited for before the run begins
    opening = StoreOpening(args.results or station.results_url, offline_ok=True)
    runner = Runner(  # the raw file is compressed after the command has said its result (below)
        station, runs_dir=args.runs_dir or station.runs_dir, store=None, operator=args.operator, duts=args.dut,
        compact_later=True,
    )
    previous = {}
    signalled: list[int] = []  # the signal that aborted the run: its exit code once the run is safe

    def on_signal(signum, _frame):
        signalled.append(signum)
        runner.abort(signal.Signals(signum).name)

    for sig in (signal.SIGINT, signal.SIGTERM):
        previous[sig] = signal.signal(sig, on_signal)
    display = None
    try:
        try:
            station.open()
        except Exception as exc:  # noqa: BLE001 - a station that does not open is reported, not traced
            _err(f"station {station.id!r} did not open: {type(exc).__name__}: {exc}")
            station.close()
            return EXIT_BAD_OUTCOME
        try:  # the opened devices' own limits (an FPGA loop's force limit), before anything moves
            check_station(proc, station)
        except ValueError as exc:
            _err(str(exc))
            return EXIT_USAGE
        runner.store = opening.result()  # a store that cannot be opened at all: one line, the station closed
        for kind, at_s in faults:
            station.schedule_fault(kind, at_s)
        if not args.json and sys.stdout.isatty():
            from bench.progress import RichProgress

            display = RichProgress(runner.bus)
        rec = runner.run(proc)
    finally:
        if display is not None:
            display.close()
        station.close()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    js = rec.as_json()
    apply_limits(js, lab_limits, {m.name for m in proc_cls.measurements})  # and the truths outside, flagged
    report = None
    if args.report and js.get("raw_file"):  # beside the raw file, same name with .html (and .pdf)
        report = _write_report(js["raw_file"], runner.store.get_run(js["run_id"]) if not rec.store_error else None,
                               pdf=args.pdf)
    if args.json:
        print(json.dumps(js))
    else:
        print_record(js)
        if runner.pending_compaction is not None:
            print("  the raw file is complete and readable now; a background process compresses its streams "
                  "and replaces it atomically (bench.compaction)")
        for path in report or []:
            print(f"  report {path}")
    sys.stdout.flush()
    if runner.pending_compaction is not None:  # last: the limits' annotation and the report have read it
        from bench.recorder import compact_in_background

        compact_in_background(runner.pending_compaction)
    _warn_unfired_faults(station, faults)
    if rec.store_error:  # the run's record is not in the store (it is in the spool): not a clean exit
        _err(rec.store_error)
    if signalled and rec.outcome == "ABORTED":  # after the safe state: 130 (SIGINT) / 143 (SIGTERM)
        return exit_for_signal(signalled[0])
    if rec.store_error:
        return EXIT_BAD_OUTCOME
    lab_outcome = (js.get("limits") or {}).get("outcome")
    return EXIT_BAD_OUTCOME if rec.outcome in BAD_OUTCOMES or lab_outcome in BAD_OUTCOMES else EXIT_OK
