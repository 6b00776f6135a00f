"""`gyrobench list`: the procedures (with parameters and measurements), stations, drivers, faults."""

from __future__ import annotations

import argparse
import json

from .common import EXIT_OK


def add_parser(sub) -> None:
    """Register `list`."""
    lst = sub.add_parser("list", help="procedures (with parameters), stations, drivers, fault kinds")
    lst.add_argument("--json", action="store_true")
    lst.set_defaults(func=cmd)


def cmd(args: argparse.Namespace) -> int:
    from bench.devices import DRIVERS
    from bench.fault_kinds import FAULTS
    from bench.station_config import builtin_stations
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
