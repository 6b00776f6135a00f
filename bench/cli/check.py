"""`gyrobench check-station FILE`: every problem of a station file, one line each; nothing opened."""

from __future__ import annotations

import argparse
import json

from .common import EXIT_OK, EXIT_USAGE


def add_parser(sub) -> None:
    """Register `check-station`."""
    check = sub.add_parser("check-station", help="check a station file (or built-in station): every problem, one "
                                                 "line each; opens no device")
    check.add_argument("station", help="a station TOML file or a built-in station name")
    check.add_argument("--json", action="store_true", help='print {"station": ..., "problems": [...]}')
    check.set_defaults(func=cmd)


def cmd(args: argparse.Namespace) -> int:
    from bench.station_config import load_config, station_problems
    from bench.validation import printable

    problems = station_problems(args.station)
    if args.json:
        print(json.dumps({"station": args.station, "problems": problems}))
        return EXIT_USAGE if problems else EXIT_OK
    if problems:
        for line in problems:
            print(printable(line))
        print(f"{args.station}: {len(problems)} problem(s)")
        return EXIT_USAGE
    cfg = load_config(args.station)
    kind = "simulated" if cfg.simulation is not None else "real"
    slots = f", {len(cfg.slots)} slots" if cfg.slots else ""
    print(f"{cfg.source}: ok: station {cfg.id!r} ({kind}), devices {', '.join(sorted(cfg.devices))}{slots}")
    return EXIT_OK
