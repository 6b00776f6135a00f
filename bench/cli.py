"""The `gyrobench` command line: run, list, runs, show, analyze, report, sim (and demo, gui)."""

from __future__ import annotations

import argparse
import json
import math
import signal
import sys
import time
from typing import Any

EXIT_OK, EXIT_BAD_OUTCOME, EXIT_USAGE = 0, 1, 2
BAD_OUTCOMES = ("ERROR", "ABORTED", "FAIL")


def _cmd_demo(args: argparse.Namespace) -> int:
    from bench.demo import run_decay_demo

    run_decay_demo(seed=args.seed, rate_dps=args.rate_dps, duration_s=args.duration_s)
    return 0


def _add_gui(sub) -> None:
    from bench.gui.cli_args import add_gui_subcommand

    add_gui_subcommand(sub)


def _err(msg: str) -> None:
    print(f"gyrobench: {msg}", file=sys.stderr)


def _parse_sets(items: list[str]) -> dict[str, str]:
    out: dict[str, str] = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or not name:
            raise ValueError(f"--set {item!r}: expected name=value")
        out[name.strip()] = value.strip()
    return out


def _store(url: str | None):
    from bench.results import ResultsStore

    return ResultsStore(url)


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
            overrides["speed"] = args.speed
        station = Station.load(args.station, **overrides)
        missing = [r for r in proc_cls.requires if r not in station.config.devices]
        if missing:
            raise StationError(
                f"procedure {proc_cls.name!r} needs device role(s) {missing}; station "
                f"{station.id!r} has {sorted(station.config.devices)}"
            )
        check_station(proc, station)  # the kind of gyro and the station's limits, before anything opens
        faults = [parse_fault(f) for f in args.fault]
        if faults and not isinstance(station, SimStation):
            raise StationError(f"--fault needs a simulated station; {args.station!r} is real")
    except (ProcedureNotFound, ParamError, StationError, ValueError) as exc:
        _err(str(exc))
        return EXIT_USAGE
    store = _store(args.results or station.results_url)
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
    if args.report and js.get("raw_file"):  # beside the raw file, same name with .html
        report = _write_report(js["raw_file"], store.get_run(js["run_id"]) if store else None)
    if args.json:
        print(json.dumps(js))
    else:
        _print_record(js)
        if report is not None:
            print(f"  report {report}")
    return EXIT_BAD_OUTCOME if rec.outcome in BAD_OUTCOMES else EXIT_OK


def _write_report(raw_file: str, row: dict[str, Any] | None, output: str | None = None) -> Any:
    """Render the HTML report of a recorded run beside its raw file (or to output); its path."""
    from pathlib import Path

    from bench.recorder import open_run
    from bench.report import render_report

    with open_run(raw_file) as data:
        html = render_report(data, row)
        out = Path(output or data.path.with_suffix(".html"))
    out.write_text(html)
    return out


def _print_record(js: dict[str, Any]) -> None:
    print(f"run {js['run_id']}  {js['procedure']}  {js['outcome']}  ({js['end_reason']})")
    truth = js.get("truth") or {}
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
        for p in d["params"]:
            if p["choices"] is not None:
                rng = f"one of {p['choices']}"
            elif p["low"] is None and p["high"] is None:
                rng = ""
            else:
                rng = f"[{p['low']}, {p['high']}]"
            print(f"      {p['name']} = {p['default']!r} {p['unit']}  {rng}  {p['doc']}")
    print("stations:")
    for name, path in stations.items():
        print(f"  {name}: {path}")
    print(f"drivers: {', '.join(sorted(DRIVERS))}")
    print(f"faults (--fault KIND@SECONDS): {', '.join(FAULTS)}")
    return EXIT_OK


def _cmd_runs(args: argparse.Namespace) -> int:
    rows = _store(args.results).list_runs(limit=args.limit, procedure=args.procedure)
    if args.json:
        print(json.dumps(rows, default=str))
        return EXIT_OK
    for r in rows:
        print(
            f"{r['run_id']}  {r['started_at'][:19]}  {r['station_id']:<10} {r['procedure']:<18} {r['outcome']:<9} "
            f"{'safe' if r['safe_state'] else 'UNSAFE'}  {r['end_reason']}"
        )
    return EXIT_OK


def _cmd_show(args: argparse.Namespace) -> int:
    try:
        run = _store(args.results).get_run(args.run)
    except KeyError as exc:
        _err(str(exc.args[0]))
        return EXIT_USAGE
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
    print(f"{'params':>17}: {run['params']}")
    if run["duts"]:
        print(f"{'duts':>17}: {', '.join(run['duts'])}")
    for m in run["measurements"]:
        lim = "" if m["low"] is None and m["high"] is None else f" [{m['low']}, {m['high']}]"
        t = f"  truth {run['truth'][m['name']]:.6g}" if m["name"] in run["truth"] else ""
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


def _cmd_analyze(args: argparse.Namespace) -> int:
    from procedures import ProcedureNotFound, find_procedure

    try:
        data, store, run_id = _open_recorded(args.run, args.results)
    except KeyError as exc:
        _err(str(exc.args[0]))
        return EXIT_USAGE
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
        results = proc.analysis(data)
        truth = data.truth or {}
    if store is not None:
        store.save_analysis(run_id, results)
    out = {r.name if r.dut is None else f"{r.dut}:{r.name}": r.as_json() for r in results}
    if args.json:
        print(json.dumps({"run_id": run_id, "measurements": out, "truth": truth or None}))
    else:
        print(f"re-analysis of run {run_id} ({cls.name})")
        for name, m in out.items():
            t = f"  truth {truth[name]:.6g}" if name in truth else ""
            print(f"  {name} = {m['value']} {m['unit']}  ci95 {m['ci95']}  {m['outcome']}{t}")
    return EXIT_OK


def _cmd_report(args: argparse.Namespace) -> int:


    try:
        data, store, run_id = _open_recorded(args.run, args.results)
    except KeyError as exc:
        _err(str(exc.args[0]))
        return EXIT_USAGE
    with data:
        row = store.get_run(run_id) if store is not None else None
        raw_file = str(data.path)
    print(_write_report(raw_file, row, args.output))
    return EXIT_OK


def _cmd_design(args: argparse.Namespace) -> int:
    from bench.analysis.damping_design import design_hrg_damping
    from simulators.physics.params import ParameterError, preset

    try:
        p = preset(args.preset)
        design = design_hrg_damping(
            tau_s=args.tau_s if args.tau_s is not None else p.tau_s,
            delta_inv_tau_per_s=(
                args.delta_inv_tau_per_s if args.delta_inv_tau_per_s is not None else p.delta_inv_tau_per_s
            ),
            noise_sigma=args.noise_sigma if args.noise_sigma is not None else p.noise_sigma,
            stream_hz=args.stream_hz,
            bryan_factor=args.bryan_factor if args.bryan_factor is not None else p.bryan_factor,
            split_hz=args.split_hz if args.split_hz is not None else p.split_hz,
            quadrature=args.quadrature,
            theta_tau_deg=p.theta_tau_deg,
            theta_w_deg=p.theta_w_deg,
            model=args.model,
        )
    except (ParameterError, ValueError) as exc:
        _err(str(exc))
        return EXIT_USAGE
    print(design.summary())
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
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser("demo", help="simulated HRG free decay on a spinning table, with a summary")
    demo.add_argument("--seed", type=int, default=0)
    demo.add_argument("--rate-dps", type=float, default=500.0)
    demo.add_argument("--duration-s", type=float, default=300.0)
    demo.set_defaults(func=_cmd_demo)

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
    run.set_defaults(func=_cmd_run)

    design = sub.add_parser("design", help="experiment design: table rate and record length for a procedure")
    design.add_argument("procedure", choices=["hrg-damping"])
    design.add_argument("--preset", default="hrg", help="resonator preset giving the defaults below")
    design.add_argument("--tau-s", type=float, default=None)
    design.add_argument("--delta-inv-tau-per-s", type=float, default=None)
    design.add_argument("--noise-sigma", type=float, default=None, help="white noise per channel per streamed sample")
    design.add_argument("--stream-hz", type=float, default=1000.0)
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
        p.set_defaults(func=func)

    sim = sub.add_parser("sim", help="serve the simulated devices standalone in real time; print their addresses")
    sim.add_argument("--station", default="sim-hrg")
    sim.add_argument("--speed", type=float, default=1.0, help="x real time")
    sim.add_argument("--seed", type=int, default=None)
    sim.add_argument("--duration-s", type=float, default=None, help="stop after this many wall seconds")
    sim.add_argument("--fault", action="append", default=[], metavar="KIND@SECONDS")
    sim.set_defaults(func=_cmd_sim)
    _add_gui(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return int(args.func(args))


if __name__ == "__main__":
    sys.exit(main())
