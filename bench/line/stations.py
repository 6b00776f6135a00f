"""A line station as its own process, for the concurrency test and the benchmarks:

    python -m bench.line.stations URL RUNS_DIR STATION_NO UNITS [--synthetic RECORD.json] [--station-file FILE]
                                  [--no-pdf]

runs UNITS units of the `ci-spin` sequence on a simulated station writing to the line database at
URL (or, with --synthetic, saves UNITS copies of a record as fast as it can); prints one JSON line
with the serials it recorded and the time it took.  `--station-file` replaces the sequence's station (the
concurrency test gives its eight stations a table watchdog that a starved heartbeat on a loaded
2-core machine does not trip: the test is of the database, not of the watchdog); `--no-pdf` writes each
unit's certificate as HTML only (no WeasyPrint: ~1 s of CPU a station the database test does not need)."""

from __future__ import annotations

import argparse
import copy
import json
import time
from pathlib import Path


class _Yes:
    """The operator of a headless station: every question answered yes."""

    def scan_serial(self) -> str:
        raise RuntimeError("serials are given")

    def confirm(self, question: str) -> bool:
        return True

    def show_outcome(self, serial: str, outcome: str, summary: str) -> None:
        pass


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m bench.line.stations")
    p.add_argument("url")
    p.add_argument("runs_dir")
    p.add_argument("station", type=int)
    p.add_argument("units", type=int)
    p.add_argument("--synthetic", default=None)
    p.add_argument("--sequence", default="ci-spin")
    p.add_argument("--station-file", default=None, help="station file instead of the sequence's station")
    p.add_argument("--no-pdf", action="store_true", help="certificates as HTML only (no WeasyPrint)")
    args = p.parse_args(argv)
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
    print(json.dumps({"station": args.station, "serials": serials, "elapsed_s": time.perf_counter() - t0}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
