"""A line station as its own process, for the concurrency test and the benchmarks:

    python -m bench.line.stations URL RUNS_DIR STATION_NO UNITS [--synthetic RECORD.json] [--station-file FILE]
                                  [--no-pdf] [--stations N]

runs UNITS units of the `ci-spin` sequence on a simulated station writing to the line database at
URL (or, with --synthetic, saves UNITS copies of a record as fast as it can); prints one JSON line
with the serials it recorded and the time it took.  `--station-file` replaces the sequence's station (the
concurrency test gives its eight stations a table watchdog that a starved heartbeat on a loaded
2-core machine does not trip: the test is of the database, not of the watchdog); `--no-pdf` writes each
unit's certificate as HTML only (no WeasyPrint: ~1 s of CPU a station the database test does not need).
`--stations N` forks N stations (numbered from STATION_NO) from this process once it has imported what a
station runs, each its own process with its own connections, each printing its line: eight stations
without eight interpreters' imports (~1.2 s of CPU apiece); it fails if any station fails."""

from __future__ import annotations

import argparse
import copy
import importlib
import json
import os
import sys
import time
from pathlib import Path

#: what a station imports, imported once before `--stations` forks (the fork starts with them)
#: (the front end's driver and pyvisa's Python backend, which its first connect loads, and scipy.special,
#: table-spin's analysis: a suite pass's py-spy profile found each forked station importing them, ~0.9 s
#: of CPU apiece; the sequence's procedures and every procedure the limits check are imported by
#: loading both, below)
STATION_MODULES = ("bench.line.db", "bench.line.run", "bench.line.limits", "bench.line.sequence",
                   "bench.line.certificate", "bench.composition", "bench.results", "bench.recorder",
                   "procedures", "simulators.world", "h5py", "numba", "jinja2", "sqlalchemy", "psycopg",
                   "drivers.frontend.driver", "drivers.rate_table.modbus_driver", "drivers.fpga.link",
                   "pyvisa_py", "scipy.special")


class _Yes:
    """The operator of a headless station: every question answered yes."""

    def scan_serial(self) -> str:
        raise RuntimeError("serials are given")

    def confirm(self, question: str) -> bool:
        return True

    def show_outcome(self, serial: str, outcome: str, summary: str) -> None:
        pass


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m bench.line.stations")
    p.add_argument("url")
    p.add_argument("runs_dir")
    p.add_argument("station", type=int)
    p.add_argument("units", type=int)
    p.add_argument("--synthetic", default=None)
    p.add_argument("--sequence", default="ci-spin")
    p.add_argument("--station-file", default=None, help="station file instead of the sequence's station")
    p.add_argument("--no-pdf", action="store_true", help="certificates as HTML only (no WeasyPrint)")
    p.add_argument("--stations", type=int, default=1, help="fork this many stations, numbered from STATION_NO")
    return p


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    if args.stations <= 1:
        _say(run_station(args))
        return 0
    for name in STATION_MODULES:  # before any fork, in this single-threaded process
        importlib.import_module(name)
    if not args.synthetic:  # the sequence's procedures, and the limits' check imports every procedure
        from .limits import load_limits
        from .sequence import load_sequence

        load_limits(load_sequence(args.sequence).limits)
    from bench.composition import warm_simulators

    warm_simulators()  # the compiled kernels loaded once (a station warms them before it serves: a no-op then)
    first = args.station
    children = {}
    for k in range(args.stations):
        args.station = first + k
        pid = os.fork()
        if pid == 0:  # the station: its own process from here on, its own connections
            code = 1
            try:
                _say(run_station(args))
                code = 0
            except BaseException:  # noqa: BLE001 - the station's traceback, then its status
                import traceback

                traceback.print_exc()
            finally:
                sys.stderr.flush()
                os._exit(code)
        children[pid] = args.station
    failed = []
    for _ in range(len(children)):
        pid, status = os.wait()
        if os.waitstatus_to_exitcode(status) != 0:
            failed.append(f"station {children[pid]} ended with {os.waitstatus_to_exitcode(status)}")
    for line in failed:
        print(line, file=sys.stderr)
    return 1 if failed else 0


def _say(result: dict) -> None:
    """One JSON line in one write (stations forked from one process share its stdout)."""
    os.write(sys.stdout.fileno(), (json.dumps(result) + "\n").encode())


def run_station(args: argparse.Namespace) -> dict:
    """Run one station; what it prints."""
    from .db import LineDB

    db = LineDB(args.url)
    serials = []
    t0 = time.perf_counter()
    if args.synthetic:
        template = json.loads(Path(args.synthetic).read_text())
        for k in range(args.units):
            rec = copy.deepcopy(template)
            rec.update(serial=f"S{args.station}-{k}", station=f"st{args.station}", attempt=1)
            db.save(rec)
            serials.append(rec["serial"])
    else:
        from bench.composition import load_station
        from bench.results import ResultsStore

        from .limits import load_limits
        from .run import LineContext, run_unit
        from .sequence import load_sequence

        seq = load_sequence(args.sequence)
        station = args.station_file or seq.station
        runs_dir = Path(args.runs_dir) / f"st{args.station}"
        store = ResultsStore(args.url, offline_ok=True, spool_dir=runs_dir / "spool")
        ctx = LineContext(seq, load_limits(seq.limits), f"st{args.station}", "op", runs_dir, store=store, db=db,
                          lot="concurrent", pdf=not args.no_pdf)
        for k in range(args.units):
            serial = f"S{args.station}-{k}"
            for rec in run_unit(ctx, lambda: load_station(station, seed=args.station), serial, _Yes(),
                                first_attempt=db.next_attempt(serial)):
                serials.append(rec["serial"])
        store.close()
    db.close()
    return {"station": args.station, "pid": os.getpid(), "serials": serials, "elapsed_s": time.perf_counter() - t0}


if __name__ == "__main__":
    raise SystemExit(main())
