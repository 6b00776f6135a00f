"""The `gyrobench` command line: run, list, runs, show, analyze, report, sim (and gui)."""

from __future__ import annotations

import argparse
import json
import math
import signal
import sys
import threading
import time
from typing import Any

EXIT_OK, EXIT_BAD_OUTCOME, EXIT_USAGE = 0, 1, 2
EXIT_INTERNAL, EXIT_INTERRUPTED, EXIT_BROKEN_PIPE = 70, 130, 141
BAD_OUTCOMES = ("ERROR", "ABORTED", "FAIL")


def _interrupted_early(signum: int, _frame: Any) -> None:
    """SIGINT/SIGTERM while the CLI is still importing (before main()'s error boundary): one line and
    the conventional exit code, no traceback; nothing has been opened yet, so nothing to make safe."""
    import os

    os.write(2, f"gyrobench: interrupted ({signal.Signals(signum).name}) before anything started\n".encode())
    os._exit(128 + signum)


_SIGNALLED: list[str] = []  # the signal that interrupted main(), if any


def _interrupt(signum: int, _frame: Any) -> None:
    """Inside main(): SIGINT and SIGTERM raise KeyboardInterrupt (the boundary prints one line); a
    run installs its own handlers that abort it into the safe state, and puts these back after.
    The signal is remembered: a library that turns the interrupt into its own error (numpy's
    import wraps it in an ImportError) is still reported as the interruption it was."""
    _SIGNALLED.append(signal.Signals(signum).name)
    raise KeyboardInterrupt(_SIGNALLED[-1])


if __name__ == "__main__" or sys.argv[0].endswith("gyrobench"):  # the CLI's own process, not an importer
    for _sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(_sig, _interrupted_early)


class CliError(Exception):
    """A failure the user can act on (a path, a store, an option): one line and an exit code."""

    def __init__(self, message: str, code: int = EXIT_USAGE) -> None:
        super().__init__(message)
        self.code = code


def _add_gui(sub) -> None:
    from bench.gui.cli_args import add_gui_subcommand

    add_gui_subcommand(sub)


def _err(msg: str) -> None:
    print(f"gyrobench: {msg}", file=sys.stderr)


def _parse_sets(items: list[str]) -> dict[str, str]:
    """`--set NAME=VALUE` items by name, the values as typed (Param.convert parses them)."""
    from bench.validation import parse_assignment

    return dict(parse_assignment(item) for item in items)


def _store(url: str | None, **kw: Any):
    """The results store, or CliError naming it (a directory that is a file, a read-only store, a
    missing database driver)."""
    from bench.results import ResultsStore, StoreError

    try:
        return ResultsStore(url, **kw)
    except StoreError as exc:
        raise CliError(str(exc), 1) from exc
    except Exception as exc:  # noqa: BLE001 - OSError, SQLAlchemy's errors, a missing driver: one line
        raise CliError(f"results store {url or 'runs/results.sqlite'}: cannot be opened: {_reason(exc)}", 1) from exc


def _reason(exc: BaseException) -> str:
    """An exception as a short reason: OSError's text and file, SQLAlchemy's original error."""
    if isinstance(exc, OSError) and exc.strerror:
        return f"{exc.strerror}: {exc.filename}" if exc.filename else exc.strerror
    orig = getattr(exc, "orig", None)  # SQLAlchemy wraps the database driver's error
    if orig is not None:
        return f"{type(orig).__name__}: {orig}"
    return f"{type(exc).__name__}: {exc}"


def _check_runs_dir(path: str) -> None:
    """The raw-data directory exists (or is made) and takes a file, before any device moves."""
    import os
    import tempfile
    from pathlib import Path

    p = Path(path)
    if p.exists() and not p.is_dir():
        raise CliError(f"--runs-dir {path}: is a file, not a directory")
    try:
        p.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(dir=p, prefix=".gyrobench-probe-")
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise CliError(f"--runs-dir {path}: raw data cannot be written there ({_reason(exc)})") from None


def _speed(value: float | None) -> float | None:
    """--speed checked here, naming the option (not the station file)."""
    if value is None:
        return None
    from bench.validation import ValidationError, convert

    try:
        return convert("--speed", value, float, low=0.0, high=1e6)
    except ValidationError as exc:
        raise CliError(f"{exc} (allowed: 0 = lockstep, or 0 to 1e6 x real time)") from None


def _warn_unfired_faults(station: Any, faults: list[tuple[str, float]]) -> None:
    """A --fault whose time the run never reached did not test anything: say so."""
    sched = getattr(station, "faults", None)
    if sched is None or not faults:
        return
    end_s = float(getattr(station.world, "t_s", 0.0))
    for at_s, kind in list(sched.pending):
        _err(f"warning: fault {kind}@{at_s:g} s never fired: the run ended at {end_s:.1f} s")


# --- run -----------------------------------------------------------------------------------------
def _cmd_run(args: argparse.Namespace) -> int:
    from bench.engine import ParamError, Runner, check_station
    from bench.station import SimStation, Station, StationError, parse_fault
    from procedures import ProcedureNotFound, find_procedure

    try:
        proc_cls = find_procedure(args.procedure)
        params = _parse_sets(args.set)
        proc = proc_cls(params)  # parameters are checked here, before any device exists
        overrides: dict[str, Any] = {}
        if args.seed is not None:
            overrides["seed"] = args.seed
        if args.speed is not None:
            overrides["speed"] = _speed(args.speed)
        faults = [parse_fault(f) for f in args.fault]
        station = Station.load(args.station, **overrides)
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
    except (ProcedureNotFound, ParamError, StationError, ValueError) as exc:
        _err(str(exc))
        return EXIT_USAGE
    _check_runs_dir(args.runs_dir or station.runs_dir)
    # a store that is down now still takes the run's record later, through the spool
    store = _store(args.results or station.results_url, offline_ok=True)
    runner = Runner(
        station, runs_dir=args.runs_dir or station.runs_dir, store=store, operator=args.operator, duts=args.dut
    )
    previous = {}

    def on_signal(signum, _frame):
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
    report = None
    if args.report and js.get("raw_file"):  # beside the raw file, same name with .html (and .pdf)
        report = _write_report(js["raw_file"], store.get_run(js["run_id"]) if not rec.store_error else None,
                               pdf=args.pdf)
    if args.json:
        print(json.dumps(js))
    else:
        _print_record(js)
        for path in report or []:
            print(f"  report {path}")
    sys.stdout.flush()
    _warn_unfired_faults(station, faults)
    if rec.store_error:  # the run's record is not in the store (it is in the spool): not a clean exit
        _err(rec.store_error)
        return EXIT_BAD_OUTCOME
    return EXIT_BAD_OUTCOME if rec.outcome in BAD_OUTCOMES else EXIT_OK


def _write_report(raw_file: str, row: dict[str, Any] | None, output: str | None = None, pdf: bool = False) -> Any:
    """Render the HTML report (and with pdf the PDF) of a recorded run beside its raw file (or
    to output); their paths."""
    from bench.reporting import PdfUnavailable, write_report

    try:
        return write_report(raw_file, row, output, pdf=pdf)
    except PdfUnavailable as exc:  # checked before anything is written: the HTML alone, and why
        _err(str(exc))
        return write_report(raw_file, row, output)


def _print_record(js: dict[str, Any]) -> None:
    from procedures import measurement_truth

    print(f"run {js['run_id']}  {js['procedure']}  {js['outcome']}  ({js['end_reason']})")
    truth = measurement_truth(js.get("procedure"), js.get("truth"))  # by declaration
    def num(x: Any) -> str:  # as_json gives None for NaN/inf and for an open side of the limits
        return "-" if x is None else f"{x:.6g}"

    rows = [("measurement", "value", "unit", "95% interval", "limits", "outcome", "truth" if truth else "")]
    for name, m in js["measurements"].items():
        ci = "" if m["ci95"] is None else f"[{num(m['ci95'][0])}, {num(m['ci95'][1])}]"
        lim = "" if m["limits"] is None else "[" + ", ".join(num(x) for x in m["limits"]) + "]"
        t = num(truth[name]) if name in truth else ""
        rows.append((name, num(m["value"]), m["unit"], ci, lim, m["outcome"], t))
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    for r in rows:
        print("  " + "  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip())
    print(
        f"  safe state {'confirmed' if js['safe_state'] else 'NOT CONFIRMED'}; "
        f"{js['simulated_s']:.3f} s bench time, {js['wall_s']:.2f} s wall"
        + (f" ({js['speed_achieved']:.3g}x real time)" if js.get("speed_achieved") else "")
        + f"; raw {js['raw_file']}"
    )


# --- list / runs / show ------------------------------------------------------------------------
def _cmd_list(args: argparse.Namespace) -> int:
    from bench.station import DRIVERS, FAULTS, builtin_stations
    from procedures import all_procedures

    procs = {name: cls.describe() for name, cls in all_procedures().items()}
    stations = {name: str(path) for name, path in builtin_stations().items()}
    if args.json:
        print(
            json.dumps({"procedures": procs, "stations": stations, "drivers": sorted(DRIVERS), "faults": list(FAULTS)})
        )
        return EXIT_OK
    print("procedures:")
    for name, d in procs.items():
        print(f"  {name}: {d['title']}  (steps: {', '.join(d['steps'])})")
        print("    parameters:")
        for p in d["params"]:
            if p["choices"] is not None:
                rng = f"one of {p['choices']}"
            elif p["low"] is None and p["high"] is None:
                rng = ""
            else:
                rng = f"[{p['low']}, {p['high']}]"
            print(f"      {p['name']} = {p['default']!r} {p['unit']}  {rng}  {p['doc']}")
        print("    measurements:")
        for m in d["measurements"]:
            when = f"  (when {m['condition']})" if m["condition"] else ""
            print(f"      {m['name']} [{m['unit'] or '-'}]  {m['doc']}{when}")
    print("stations:")
    for name, path in stations.items():
        print(f"  {name}: {path}")
    print(f"drivers: {', '.join(sorted(DRIVERS))}")
    print(f"faults (--fault KIND@SECONDS): {', '.join(FAULTS)}")
    return EXIT_OK


def _cmd_runs(args: argparse.Namespace) -> int:
    from pathlib import Path

    from bench.results import StoreError

    spool = Path(args.runs_dir) / "spool"
    try:
        store = _store(args.results, spool_dir=spool)
        if args.sync:
            submitted, problems = store.sync()
            for problem in problems:
                _err(problem)
            print(f"submitted {len(submitted)} spooled run(s) from {spool}", file=sys.stderr)
            if problems:
                return EXIT_BAD_OUTCOME
        elif store.spool.pending():
            _err(f"{len(store.spool.pending())} run(s) wait in {spool}; `gyrobench runs --sync` submits them")
        rows = store.list_runs(limit=args.limit, procedure=args.procedure)
    except StoreError as exc:
        _err(str(exc))
        return EXIT_BAD_OUTCOME
    if args.json:
        print(json.dumps(rows, default=str))
        return EXIT_OK
    for r in rows:
        safe = "-" if r["outcome"] == "RUNNING" else "safe" if r["safe_state"] else "UNSAFE"
        where = f"on {r['host']}, process {r['pid']}" if r["outcome"] == "RUNNING" else r["end_reason"]
        print(
            f"{r['run_id']}  {r['started_at'][:19]}  {r['station_id']:<10} {r['procedure']:<18} {r['outcome']:<11} "
            f"{safe:<6}  {where}"
        )
    return EXIT_OK


def _cmd_show(args: argparse.Namespace) -> int:
    from bench.results import StoreError

    try:
        run = _store(args.results).get_run(args.run)
    except KeyError as exc:
        _err(str(exc.args[0]))
        return EXIT_USAGE
    except StoreError as exc:
        _err(str(exc))
        return EXIT_BAD_OUTCOME
    if args.json:
        print(json.dumps(run, default=str))
        return EXIT_OK
    for key in (
        "run_id",
        "procedure",
        "station_id",
        "outcome",
        "end_reason",
        "safe_state",
        "started_at",
        "simulated_s",
        "wall_s",
        "software_version",
        "operator",
        "seed",
        "raw_file",
    ):
        print(f"{key:>17}: {run[key]}")
    if run.get("host"):  # where it ran, and its last sign of life (RUNNING / INTERRUPTED)
        print(f"{'host':>17}: {run['host']} (process {run['pid']}, heartbeat {run['heartbeat_at']})")
    print(f"{'params':>17}: {run['params']}")
    if run["duts"]:
        print(f"{'duts':>17}: {', '.join(run['duts'])}")
    from procedures import measurement_truth

    truth = measurement_truth(run["procedure"], run["truth"])  # by declaration
    for m in run["measurements"]:
        lim = "" if m["low"] is None and m["high"] is None else f" [{m['low']}, {m['high']}]"
        t = f"  truth {truth[m['name']]:.6g}" if m["name"] in truth else ""
        dut = f"{m['dut']}:" if m["dut"] else ""
        print(f"  {m['source']:<7} {dut}{m['name']} = {m['value']} {m['unit']}{lim} {m['outcome']}{t}")
    return EXIT_OK


# --- analyze / report --------------------------------------------------------------------------
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
    try:
        return _open_recorded(args.run, args.results)
    except KeyError as exc:
        _err(str(exc.args[0]))
        return EXIT_USAGE
    except OSError as exc:  # not an HDF5 file, or damaged
        _err(f"cannot read the raw file of {args.run!r}: {exc}")
        return EXIT_BAD_OUTCOME


def _cmd_analyze(args: argparse.Namespace) -> int:
    from procedures import ProcedureNotFound, find_procedure

    opened = _open_for_command(args)
    if isinstance(opened, int):
        return opened
    data, store, run_id = opened
    with data:
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
    if store is not None:
        store.save_analysis(run_id, results)
    out = {r.name if r.dut is None else f"{r.dut}:{r.name}": r.as_json() for r in results}
    if args.json:
        print(json.dumps({"run_id": run_id, "measurements": out, "truth": truth or None, "incomplete": incomplete,
                          "notes": notes, "figures": [str(p) for p in figures]}))
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
    return EXIT_OK


def _write_figures(data, proc, directory: str) -> list:
    """The figures the report draws for this run, as SVG files in directory; their paths."""
    from pathlib import Path

    from bench.reporting import figures_for

    Path(directory).mkdir(parents=True, exist_ok=True)
    figs, notes = figures_for(data, proc)
    data.notes.extend(notes)
    return [f.save(directory) for f in figs]


def _cmd_report(args: argparse.Namespace) -> int:
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


def _cmd_design(args: argparse.Namespace) -> int:
    """Design the run the procedure will make: its stream rate (boxcar-decimated from the FPGA's
    sample rate, which sets the noise per fitted sample), then table rate and record length."""
    from bench.analysis.damping_design import design_hrg_damping, design_hrg_free_decay
    from procedures.hrg_damping import HrgDamping
    from procedures.hrg_free_decay import HrgFreeDecay
    from simulators.physics.params import ParameterError, preset

    proc = {"hrg-damping": HrgDamping, "hrg-free-decay": HrgFreeDecay}[args.procedure]
    try:
        p = preset(args.preset)
        stream_hz = args.stream_hz if args.stream_hz is not None else float(proc.stream_hz.default)
        if not 0 < stream_hz <= args.sample_hz:
            raise ValueError(f"--stream-hz {stream_hz:g} must be in (0, --sample-hz {args.sample_hz:g}]")
        noise = args.noise_sigma if args.noise_sigma is not None else p.noise_sigma
        kw = dict(
            tau_s=args.tau_s if args.tau_s is not None else p.tau_s,
            delta_inv_tau_per_s=(
                args.delta_inv_tau_per_s if args.delta_inv_tau_per_s is not None else p.delta_inv_tau_per_s
            ),
            noise_sigma=noise * math.sqrt(stream_hz / args.sample_hz),  # boxcar mean of sample_hz/stream_hz samples
            stream_hz=stream_hz,
            bryan_factor=args.bryan_factor if args.bryan_factor is not None else p.bryan_factor,
            split_hz=args.split_hz if args.split_hz is not None else p.split_hz,
            quadrature=args.quadrature,
            theta_tau_deg=p.theta_tau_deg,
            theta_w_deg=p.theta_w_deg,
        )
        if args.procedure == "hrg-damping":
            design = design_hrg_damping(model=args.model, lengths_tau=(0.25, 0.5, 1.0, 2.0, 3.0), **kw)
        else:
            design = design_hrg_free_decay(**kw)
    except (ParameterError, ValueError) as exc:
        _err(str(exc))
        return EXIT_USAGE
    print(design.summary())
    if args.procedure == "hrg-damping":
        r = design.recommended
        print(f"  run it: gyrobench run hrg-damping --set rate_dps={r.rate_dps:.4g} --set record_s={r.duration_s:.0f} "
              f"--set stream_hz={stream_hz:g} --set fit_model={args.model}")
    return EXIT_OK


# --- sim -----------------------------------------------------------------------------------------
def _cmd_sim(args: argparse.Namespace) -> int:
    from bench.station import SimStation, StationError

    try:
        station = SimStation(args.station, seed=args.seed, speed=args.speed)
    except StationError as exc:
        _err(str(exc))
        return EXIT_USAGE
    stop = {"flag": False}

    def on_signal(signum, _frame):
        stop["flag"] = True

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, on_signal)
    try:
        addresses = station.start_simulators()
        for kind_at in args.fault:
            from bench.station import parse_fault

            station.schedule_fault(*parse_fault(kind_at))
        print(
            json.dumps({"station": station.id, "speed": args.speed, "seed": station.seed, "devices": addresses}),
            flush=True,
        )
        t_end = math.inf if args.duration_s is None else time.monotonic() + args.duration_s
        while not stop["flag"] and time.monotonic() < t_end:
            time.sleep(0.05)
    finally:
        station.close()
    return EXIT_OK


# --- parser --------------------------------------------------------------------------------------
def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="gyrobench", description="Calibrate Coriolis vibratory gyroscopes.")
    parser.add_argument("--debug", action="store_true", help="print the traceback of an unexpected error")
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="run a procedure (a registered name or a .py file) on a station")
    run.add_argument("procedure")
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
    run.add_argument("--report", action="store_true", help="also write the run's HTML report and print its path")
    run.add_argument("--pdf", action="store_true", help="with --report: the report as a PDF too")
    run.set_defaults(func=_cmd_run)

    design = sub.add_parser("design", help="experiment design: table rate and record length for a procedure")
    design.add_argument("procedure", choices=["hrg-damping", "hrg-free-decay"])
    design.add_argument("--preset", default="hrg", help="resonator preset giving the defaults below")
    design.add_argument("--tau-s", type=float, default=None)
    design.add_argument("--delta-inv-tau-per-s", type=float, default=None)
    design.add_argument("--noise-sigma", type=float, default=None, help="white noise per channel per FPGA sample")
    design.add_argument("--sample-hz", type=float, default=1000.0, help="the FPGA's sample rate (the station's)")
    design.add_argument("--stream-hz", type=float, default=None, help="fitted sample rate (default: the procedure's)")
    design.add_argument("--bryan-factor", type=float, default=None)
    design.add_argument("--split-hz", type=float, default=None)
    design.add_argument("--quadrature", type=float, default=0.0, help="quadrature k left at the cut (amplitude 1)")
    design.add_argument("--model", choices=["exact", "patent"], default="exact", help="energy model of the fit")
    design.set_defaults(func=_cmd_design)

    lst = sub.add_parser("list", help="procedures (with parameters), stations, drivers, fault kinds")
    lst.add_argument("--json", action="store_true")
    lst.set_defaults(func=_cmd_list)

    runs = sub.add_parser("runs", help="recent runs in the results store")
    runs.add_argument("--limit", type=int, default=20)
    runs.add_argument("--procedure", default=None)
    runs.add_argument("--results", default=None)
    runs.add_argument("--json", action="store_true")
    runs.add_argument("--sync", action="store_true", help="first submit the records spooled while the store was down")
    runs.add_argument("--runs-dir", default="runs", help="directory of the raw files and their spool/ (default: runs)")
    runs.set_defaults(func=_cmd_runs)

    for name, func, helptext in (
        ("show", _cmd_show, "one run: parameters, measurements, outcome"),
        ("analyze", _cmd_analyze, "re-fit a recorded run with its procedure's analysis hook"),
        ("report", _cmd_report, "an HTML report with plots of a run"),
    ):
        p = sub.add_parser(name, help=helptext)
        p.add_argument("run", help='run id, unique prefix, "last", or a raw .h5 file')
        p.add_argument("--results", default=None)
        if name != "report":
            p.add_argument("--json", action="store_true")
        if name == "analyze":
            p.add_argument("--procedure", default=None, help="analyse with another procedure (name or file)")
        if name == "report":
            p.add_argument("-o", "--output", default=None)
            p.add_argument("--pdf", action="store_true", help="the report as a PDF too, beside the HTML")
        if name == "analyze":
            p.add_argument("--figures", default=None, metavar="DIR", help="also write the report's figures (SVG)")
        p.set_defaults(func=func)

    from bench.line.fpga_cli import add_fpga_subcommand

    add_fpga_subcommand(sub)  # fpga load|show: trims in NVM (bench/line/fpga_cli.py)
    sim = sub.add_parser("sim", help="serve the simulated devices standalone in real time; print their addresses")
    sim.add_argument("--station", default="sim-hrg")
    sim.add_argument("--speed", type=float, default=1.0, help="x real time")
    sim.add_argument("--seed", type=int, default=None)
    sim.add_argument("--duration-s", type=float, default=None, help="stop after this many wall seconds")
    sim.add_argument("--fault", action="append", default=[], metavar="KIND@SECONDS")
    sim.set_defaults(func=_cmd_sim)
    _add_gui(sub)
    from bench.line.cli import add_line_subcommand  # the production line's commands

    add_line_subcommand(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run one command.  The one error boundary: a known failure is one line and an exit code;
    anything else is one line and a saved traceback (printed with --debug), never a bare trace."""
    import os

    argv = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in argv or bool(os.environ.get("GYROBENCH_DEBUG"))  # anywhere on the line
    argv = [a for a in argv if a != "--debug"]
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, _interrupt)
        signal.signal(signal.SIGTERM, _interrupt)
    try:
        args = build_parser().parse_args(argv)
        code = int(args.func(args))
        sys.stdout.flush()  # a closed pipe shows here, inside the boundary, not at interpreter exit
        return code
    except BrokenPipeError:  # `gyrobench runs | head`: the reader left; say nothing more
        _silence_stdout()
        return EXIT_BROKEN_PIPE
    except KeyboardInterrupt as exc:
        _err("interrupted (SIGTERM)" if str(exc) == "SIGTERM" else "interrupted (Ctrl-C)")
        return EXIT_INTERRUPTED
    except CliError as exc:
        _err(str(exc))
        return exc.code
    except Exception as exc:  # noqa: BLE001 - the boundary: classify, never print a bare traceback
        if _SIGNALLED:  # the interrupt surfaced as another error (inside an import, a library)
            _err("interrupted (SIGTERM)" if _SIGNALLED[-1] == "SIGTERM" else "interrupted (Ctrl-C)")
            return EXIT_INTERRUPTED
        return _report_exception(exc, debug)


def _known_error(exc: BaseException) -> str | None:
    """The one-line message of an error the user can act on, or None for an unexpected one."""
    from bench.validation import ValidationError

    station_error = getattr(sys.modules.get("bench.station"), "StationError", ())
    param_error = getattr(sys.modules.get("bench.engine.params"), "ParamError", ())
    not_found = getattr(sys.modules.get("procedures"), "ProcedureNotFound", ())
    if isinstance(exc, (ValidationError, *[c for c in (station_error, param_error, not_found) if c])):
        return str(exc)
    if isinstance(exc, OSError) and exc.strerror:
        return _reason(exc)
    sa_exc = sys.modules.get("sqlalchemy.exc")
    if sa_exc is not None and isinstance(exc, sa_exc.SQLAlchemyError):
        return f"results store: {_reason(exc)}"
    return None


def _report_exception(exc: BaseException, debug: bool) -> int:
    import traceback

    text = "".join(traceback.format_exception(exc))
    known = _known_error(exc)
    if debug:
        print(text, file=sys.stderr, end="")
    if known is not None:
        _err(known)
        return EXIT_USAGE if isinstance(exc, ValueError | LookupError) else EXIT_BAD_OUTCOME
    saved = _save_traceback(text)
    where = f"traceback saved to {saved}" if saved else "the traceback could not be saved"
    _err(f"internal error: {type(exc).__name__}: {exc} ({where}; --debug prints it)")
    return EXIT_INTERNAL


def _save_traceback(text: str) -> str | None:
    """Write a traceback to a file in the temporary directory; its path (None if that failed)."""
    import os
    import tempfile
    from pathlib import Path

    try:
        folder = Path(tempfile.gettempdir()) / "gyrobench"
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / f"traceback-{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}.txt"
        path.write_text(" ".join(sys.argv) + "\n\n" + text)
        return str(path)
    except OSError:
        return None


def _silence_stdout() -> None:
    """After a broken pipe, point stdout at /dev/null so the interpreter's exit flush is quiet."""
    import os

    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):
        pass


if __name__ == "__main__":
    sys.exit(main())
