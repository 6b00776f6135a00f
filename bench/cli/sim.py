"""`gyrobench sim`: a station's simulated devices served standalone in real time."""

from __future__ import annotations

import argparse
import json
import math
import signal
import time

from .common import EXIT_OK, EXIT_USAGE, _err, exit_for_signal


def add_parser(sub) -> None:
    """Register `sim` and its options."""
    sim = sub.add_parser("sim", help="serve the simulated devices standalone in real time; print their addresses")
    sim.add_argument("--station", default="sim-hrg")
    sim.add_argument("--speed", type=float, default=1.0, help="x real time")
    sim.add_argument("--seed", type=int, default=None)
    sim.add_argument("--duration-s", type=float, default=None, help="stop after this many wall seconds")
    sim.add_argument("--fault", action="append", default=[], metavar="KIND@SECONDS")
    sim.set_defaults(func=cmd)


def cmd(args: argparse.Namespace) -> int:
    from bench.composition.sim_station import SimStation
    from bench.devices import StationError

    try:
        station = SimStation(args.station, seed=args.seed, speed=args.speed)
    except StationError as exc:
        _err(str(exc))
        return EXIT_USAGE
    stop: dict = {"flag": False, "signum": None}

    def on_signal(signum, _frame):
        stop["flag"], stop["signum"] = True, signum

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, on_signal)
    try:
        addresses = station.start_simulators()
        for kind_at in args.fault:
            from bench.fault_kinds import parse_fault

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
    # stopped by a signal (Ctrl-C, the service manager): 130 / 143, as a shell reports it
    return EXIT_OK if stop["signum"] is None else exit_for_signal(stop["signum"])
