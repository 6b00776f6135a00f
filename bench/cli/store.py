"""`gyrobench runs` and `gyrobench show`: the runs in the results store, and one run's record."""

from __future__ import annotations

import argparse
import json
import sys

from .common import EXIT_BAD_OUTCOME, EXIT_OK, EXIT_USAGE, _err, _store

MAX_LIMIT = 1_000_000  # runs listed at most


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
    from bench.validation import convert

    limit = convert("--limit", args.limit, int, low=1, high=MAX_LIMIT)  # SQLite takes 64-bit ints only
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
        rows = store.list_runs(limit=limit, procedure=args.procedure)
    except StoreError as exc:
        _err(str(exc))
        return EXIT_BAD_OUTCOME
    code = EXIT_BAD_OUTCOME if problems else EXIT_OK  # a record refused or left in the spool: not clean
    if args.json:
        print(json.dumps(rows, default=str))
        return code
    if not rows:
        what = f"no {args.procedure} runs" if args.procedure else "no runs yet"
        print(f"{what} in {store.display_url}", file=sys.stderr)
    for r in rows:
        safe = "-" if r["outcome"] == "RUNNING" else "safe" if r["safe_state"] else "UNSAFE"
        where = f"on {r['host']}, process {r['pid']}" if r["outcome"] == "RUNNING" else r["end_reason"]
        print(
            f"{r['run_id']}  {r['started_at'][:19]}  {r['station_id']:<10} {r['procedure']:<18} {r['outcome']:<11} "
            f"{safe:<6}  {where}"
        )
    return code


SHOW_KEYS = ("run_id", "procedure", "station_id", "outcome", "end_reason", "safe_state", "started_at",
             "simulated_s", "wall_s", "software_version", "operator", "seed", "raw_file")


def _run_from_file(path: str) -> dict:
    """A raw .h5 file's record in the shape `ResultsStore.get_run` gives (measurements with their
    intervals, all the run's own), for `show FILE`."""
    from bench.recorder import open_run

    with open_run(path) as data:
        a = data.attrs
        row = {k: a.get(k) for k in SHOW_KEYS}
        row["raw_file"] = str(data.path)
        row["params"], row["truth"] = data.params, data.truth or {}
        row["duts"] = [str(d) for d in a.get("duts") or []]
        row["measurements"] = []
        for m in data.measurements():
            ci = m.get("ci95") or [None, None]
            row["measurements"].append({**m, "ci95_low": ci[0], "ci95_high": ci[1], "source": "run"})
    return row


def cmd_show(args: argparse.Namespace) -> int:
    from pathlib import Path

    from bench.results import StoreError

    try:
        if args.run.endswith(".h5") and Path(args.run).is_file():  # a raw file: no store needed
            from bench.recorder import NotARunFile  # h5py and numpy only for a raw file (issue 36)

            try:
                run = _run_from_file(args.run)
            except NotARunFile as exc:
                _err(str(exc))
                return EXIT_USAGE
        else:
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
    _print_run(run)
    return EXIT_OK


def _num(x) -> str:
    return "-" if x is None else f"{x:.6g}" if isinstance(x, float) else str(x)


def _print_run(run: dict) -> None:
    """One run as text; every stored value through `printable` (a serial recorded before labels
    were checked may hold an escape)."""
    from bench.validation import printable
    from procedures import measurement_truth

    for key in SHOW_KEYS:
        print(f"{key:>17}: {printable(run.get(key))}")
    if run.get("host"):  # where it ran, and its last sign of life (RUNNING / INTERRUPTED)
        print(f"{'host':>17}: {printable(run['host'])} (process {run['pid']}, heartbeat {run['heartbeat_at']})")
    print(f"{'params':>17}: {printable(run['params'])}")
    if run["duts"]:
        print(f"{'duts':>17}: {', '.join(printable(d) for d in run['duts'])}")
    truth = measurement_truth(run["procedure"], run["truth"])  # by declaration
    for source, title in (("run", "measurements (the run's own)"),
                          ("analyze", "re-analysis (gyrobench analyze; the run's own results are above)")):
        rows = [m for m in run["measurements"] if (m.get("source") or "run") == source]
        if not rows:
            continue
        print(f"{title}:")
        for m in rows:
            lim = "" if m["low"] is None and m["high"] is None else f"  limits [{_num(m['low'])}, {_num(m['high'])}]"
            ci = ("" if m.get("ci95_low") is None or m.get("ci95_high") is None
                  else f"  95% [{_num(m['ci95_low'])}, {_num(m['ci95_high'])}]")
            t = f"  truth {truth[m['name']]:.6g}" if m["name"] in truth else ""
            dut = f"{printable(m['dut'])}:" if m["dut"] else ""
            print(f"  {dut}{m['name']} = {_num(m['value'])} {m['unit']}{ci}{lim}  {m['outcome']}{t}")
