"""The `gyrobench gui` subcommand's arguments (registered by bench.cli; no Qt import here)."""

from __future__ import annotations

import argparse


def add_gui_subcommand(sub) -> argparse.ArgumentParser:
    """Register `gui` on the CLI's subparsers."""
    p = sub.add_parser("gui", help="the lab engineer's window (live plots, Start/Pause/Abort, replay)")
    p.add_argument("--station", default=None, help="station name (sim-hrg, sim-mems) or station file")
    p.add_argument("--run", default=None, metavar="PROC", help="procedure to select (and run with --screenshot)")
    p.add_argument("--screenshot", default=None, metavar="FILE", help="run headless, save a PNG of the window, exit")
    p.add_argument("--at", dest="at_s", type=float, default=None, metavar="SECONDS",
                   help="simulated second at which the screenshot is taken (default: end of the run)")
    p.add_argument("--speed", default=None, help="simulated clock speed: 1, 10, 100 or max")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="a procedure parameter (repeatable)")
    p.add_argument("--open", dest="open_run", default=None, metavar="RUN.h5", help="replay a recorded run")
    p.add_argument("--start", action="store_true", help="start the --run procedure as soon as the window is up")
    p.add_argument("--operator", action="store_true",
                   help="the operator station: log in, pick a line sequence, scan serials (with --run PROC: one "
                        "procedure a unit, no line records)")
    p.add_argument("--sequence", default=None, help="with --operator: the line sequence to offer first")
    p.add_argument("--runs-dir", dest="runs_dir", default=None, help="with --operator: where records go")
    p.set_defaults(func=cmd_gui)
    return p


def cmd_gui(args: argparse.Namespace) -> int:
    from .app import parse_speed, run_gui

    speed = None if args.speed is None else parse_speed(args.speed)
    from bench.validation import parse_assignment

    params = dict(parse_assignment(item) for item in args.set)  # the same reading as `gyrobench run --set`
    if args.operator and args.run is None:
        from .operator_station import run_station

        return run_station(args.station, sequence=args.sequence, runs_dir=args.runs_dir, seed=args.seed,
                           screenshot=args.screenshot)
    if args.operator:
        from .operator_view import run_operator

        return run_operator(args.station, run=args.run, params=params, seed=args.seed, screenshot=args.screenshot)
    try:
        return run_gui(args.station, run=args.run, screenshot=args.screenshot, at_s=args.at_s, seed=args.seed,
                       speed=speed, open_run=args.open_run, params=params, start=args.start)
    except KeyboardInterrupt as exc:  # a signal outside the event loop: the run's safe state is done
        import sys

        print(f"gyrobench gui: interrupted ({exc or 'SIGINT'})", file=sys.stderr)
        return 143 if str(exc) == "SIGTERM" else 130
