"""Benchmark (issue 36): the lockstep's link checks issued concurrently rather than in turn.

At every 0.4 s grid point `Station.check_links` asks each device for a sign of life: the FPGA
link's sync (it waits for its reader to catch up with the clock) in the calling thread, while the
table's Modbus status read and the front end's *IDN?, each a round trip on its own transport, go
out at once from a small pool (`Station._run_checks`); every check is finished before the
checkpoint returns and the first error in the stable order is raised, so every safety rule stands.
Runs alternate, in one process, between that and the checks in turn (as before: `_run_checks`
replaced by `run_checks_serial`) on the default seed-0 hrg-damping (case (c) of
benchmarks/sim_world_speed.py: x real time per wall s and per CPU s of the process, every thread),
and the two raw files are compared dataset by dataset (bit-identical, wall-clock datasets aside,
as benchmarks/sim_identical.py does).

Run: .venv/bin/python benchmarks/link_checks_concurrent.py [--repeat 3]

Measured 2026-11-28, load average 9-10 from other jobs on the 2 cores, medians of 3 alternating
runs (x real time per wall s / per CPU s), the experiment's first form (check_links patched):
  in turn  188 / 397   concurrent 289 / 418   (raw files: every dataset identical)
  in turn  169 / 386   concurrent 230 / 414   (37/37 datasets bit-identical)
and with the adopted form (`_run_checks`), load ~9:
  in turn  363 / 421   concurrent 399 / 402   (37/37 datasets bit-identical)
i.e. x1.1-1.54 per wall s, x0.95-1.07 per CPU s (the round trips overlap; the CPU is the same work).  Separate processes on two trees (sim_world_speed
(c), load 8-16) were within the load's noise: 189 / 329, 192 / 338, 225 / 326 in turn against
290 / 382, 192 / 311, 208 / 291, 148 / 309 concurrent.  benchmarks/sim_identical.py: damping,
allan and selfcal identical with the change.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
from pathlib import Path

import h5py

sys.path.insert(0, str(Path(__file__).resolve().parent))
from sim_world_speed import damping_procedure  # noqa: E402

from bench import station as station_module  # noqa: E402

_CONCURRENT = station_module.Station._run_checks


def run_checks_serial(self, order: list[str]) -> dict:
    """The link checks in turn, as before issue 36: the first error raised at once."""
    return {role: self.spec(role).health(self.devices[role], self._stream_since.get(role)) for role in order}


def datasets(path: Path) -> dict[str, bytes]:
    """Every dataset's bytes but wall-clock ones (benchmarks/sim_identical.py's rule)."""
    out: dict[str, bytes] = {}

    def visit(name: str, obj: object) -> None:
        if isinstance(obj, h5py.Dataset) and "wall" not in name.rsplit("/", 1)[-1]:
            value = obj[...]
            # text (the log, the measurements): the strings, not the object array's pointers
            out[name] = repr(value.tolist()).encode() if value.dtype.kind == "O" else value.tobytes()

    with h5py.File(path, "r") as f:
        f.visititems(visit)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    got: dict[str, list[tuple[float, float]]] = {"serial": [], "concurrent": []}
    files: dict[str, Path] = {}
    for _ in range(args.repeat):
        for label, check in (("serial", run_checks_serial), ("concurrent", _CONCURRENT)):
            station_module.Station._run_checks = check
            runs = tempfile.mkdtemp(prefix=f"gyrobench-{label}-")
            got[label].append(damping_procedure(runs))
            files[label] = next(Path(runs).glob("*.h5"))
    station_module.Station._run_checks = _CONCURRENT
    for label, rows in got.items():
        print(f"{label:10s}: median {statistics.median(w for w, _ in rows):,.0f}x per wall s, "
              f"{statistics.median(c for _, c in rows):,.0f}x per CPU s; runs "
              + ", ".join(f"{w:,.0f}/{c:,.0f}" for w, c in rows))
    a, b = datasets(files["serial"]), datasets(files["concurrent"])
    same = [k for k in a if b.get(k) == a[k]]
    print(f"raw files: {len(same)}/{len(a)} datasets bit-identical"
          + ("" if len(same) == len(a) == len(b) else f"; differ: {sorted(set(a) ^ set(same))}"))


if __name__ == "__main__":
    main()
