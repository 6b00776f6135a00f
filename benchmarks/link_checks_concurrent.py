"""Experiment (issue 36): the lockstep's link checks issued concurrently rather than in turn.

At every 0.4 s grid point `Station.check_links` asks each device for a sign of life in a stable
order: the FPGA link's sync (it waits for its reader to catch up with the clock), then the table's
Modbus status read and the front end's *IDN?, each a round trip on its own transport.  Here
(`check_links_concurrent`) the two round trips go to a thread pool at once while the main thread
does the FPGA's sync; every check is finished before the checkpoint returns (nothing in flight when
the safe state talks to the devices) and the first error in the stable order is raised, rows
recorded as before, so every safety rule stands.  Runs alternate, in one process, between the stock
`check_links` and this one on the default seed-0 hrg-damping (case (c) of
benchmarks/sim_world_speed.py: x real time per wall s and per CPU s of the process, every thread),
and the two raw files are compared dataset by dataset (wall-clock datasets aside, as
benchmarks/sim_identical.py does).

Run: .venv/bin/python benchmarks/link_checks_concurrent.py [--repeat 3]

Measured 2026-11-28, medians of 3 alternating runs (x real time per wall s / per CPU s), raw files
37/37 datasets bit-identical each time (and benchmarks/sim_identical.py identical with the change):
  load average 9-10:  in turn 188 / 397   concurrent 289 / 418
  load average 9-10:  in turn 169 / 386   concurrent 230 / 414
  load average ~9:    in turn 363 / 421   concurrent 399 / 402
  load average 1.3:   in turn 401 / 382   concurrent 336 / 294   (a quiet machine: slower)
  load average 1.0:   in turn 421 / 402   concurrent 361 / 313   (2 runs each)
On a busy machine the overlap hides some waiting for a core; on a quiet one the pool's hand-offs
under the one GIL (the simulators' servers are threads of the same process) cost more than the
round trips they overlap (x0.84 per wall s, x0.77 per CPU s).  Not adopted: the target is the
quiet machine's speed (benchmarks/sim_world_speed.py (c)).
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import h5py
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from sim_world_speed import damping_procedure  # noqa: E402

from bench import station as station_module  # noqa: E402

_SERIAL = station_module.Station.check_links
_POOL = ThreadPoolExecutor(max_workers=2, thread_name_prefix="link-check")


def check_links_concurrent(self) -> None:
    """Station.check_links with the round trips issued at once (see the module's docstring)."""
    now_sim, now_wall = self.clock.now(), time.monotonic()
    last_sim, last_wall = self._last_health
    if getattr(self.clock, "lockstep", False):
        grid = self.clock.LOCKSTEP_GRID_S
        if last_sim > -math.inf and math.floor(now_sim / grid + 1e-9) <= math.floor(last_sim / grid + 1e-9):
            return
    elif now_sim - last_sim < self.HEALTH_EVERY_SIM_S and now_wall - last_wall < self.HEALTH_EVERY_WALL_S:
        return
    self._last_health = (now_sim, now_wall)
    roles = self._health_roles()
    order = [r for r in roles if self.spec(r).stream] + [r for r in roles if self.spec(r).stream is None]
    order = [r for r in order if self.spec(r).health is not None]
    futures = {r: _POOL.submit(self.spec(r).health, self.devices[r], self._stream_since.get(r))
               for r in order if not self.spec(r).stream}
    results, first_error = {}, None
    for role in order:  # every check finished before anything is raised: nothing left in flight
        try:
            results[role] = (futures[role].result() if role in futures
                             else self.spec(role).health(self.devices[role], self._stream_since.get(role)))
        except BaseException as exc:  # noqa: BLE001 - the first in the stable order is raised
            first_error = first_error or exc
    if first_error is not None:
        raise first_error
    for role in order:
        spec, device, rows = self.spec(role), self.devices[role], results[role]
        columns = spec.health_columns or getattr(device, "health_columns", ())
        if columns and rows is not None and self._ctx is not None:
            pending = self._health_rows.setdefault(role, (("t_s", *columns), []))[1]
            pending.append(np.column_stack([[now_sim], rows]))
    if self._health_rows and (
        now_wall - self._health_sent_wall >= self.HEALTH_BLOCK_WALL_S
        or max(len(rows) for _, rows in self._health_rows.values()) >= self.HEALTH_BLOCK_ROWS
    ):
        self._send_health_rows()


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
        for label, check in (("serial", _SERIAL), ("concurrent", check_links_concurrent)):
            station_module.Station.check_links = check
            runs = tempfile.mkdtemp(prefix=f"gyrobench-{label}-")
            got[label].append(damping_procedure(runs))
            files[label] = next(Path(runs).glob("*.h5"))
    station_module.Station.check_links = _SERIAL
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
