"""`gyrobench runs` and `gyrobench show`: the runs in the results store, and one run's record."""

from __future__ import annotations

import argparse
import json
import sys

from .common import EXIT_BAD_OUTCOME, EXIT_OK, EXIT_USAGE, _err, _store


def add_parser(sub) -> None:
    """Register `runs` and `show`."""
    runs = sub.add_parser("runs", help="recent runs in the results store")
    runs.add_argument("--limit", type=int, default=20)
    runs.add_argument("--procedure", default=None)
    runs.add_argument("--results", default=None)
    runs.add_argument("--json", action="store_true")
    runs.add_argument("--sync", action="store_true", help="first submit the records spooled while the store was down")
    runs.add_argument("--runs-dir", default="runs", help="directory of the raw files and their spool/ (default: runs)")
    runs.set_defaults(func=cmd_runs)

    show = sub.add_parser("show", help="one run: parameters, measurements, outcome")
    show.add_argument("run", help='run id, unique prefix, "last", or a raw .h5 file')
    show.add_argument("--results", default=None)
    show.add_argument("--json", action="store_true")
    show.set_defaults(func=cmd_show)


def cmd_runs(args: argparse.Namespace) -> int:
    from pathlib import Path

    from bench.results import StoreError

    spool = Path(args.runs_dir) / "spool"
    problems: list[str] = []
    try:
        store = _store(args.results, spool_dir=spool)
        if args.sync:
            submitted, problems = store.sync()
            for problem in problems:
                _err(problem)
            print(f"submitted {len(submitted)} spooled run(s) from {spool}", file=sys.stderr)
        elif store.spool.pending():
            _err(f"{len(store.spool.pending())} run(s) wait in {spool}; `gyrobench runs --sync` submits them")
        if store.spool.quarantined():  # refused by the store: a person decides (see each .reason)
            _err(f"{len(store.spool.quarantined())} refused record(s) wait in {store.spool.quarantine_dir}, each "
                 "with a .reason file beside it")
        rows = store.list_runs(limit=args.limit, procedure=args.procedure)
    except StoreError as exc:
        _err(str(exc))
        return EXIT_BAD_OUTCOME
    code = EXIT_BAD_OUTCOME if problems else EXIT_OK  # a record refused or left in the spool: not clean
    if args.json:
        print(json.dumps(rows, default=str))
        return code
    for r in rows:
        safe = "-" if r["outcome"] == "RUNNING" else "safe" if r["safe_state"] else "UNSAFE"
        where = f"on {r['host']}, process {r['pid']}" if r["outcome"] == "RUNNING" else r["end_reason"]
        print(
            f"{r['run_id']}  {r['started_at'][:19]}  {r['station_id']:<10} {r['procedure']:<18} {r['outcome']:<11} "
            f"{safe:<6}  {where}"
        )
    return code


def cmd_show(args: argparse.Namespace) -> int:
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
