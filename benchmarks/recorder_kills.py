"""Benchmark: SIGKILL a recorder's writer at random moments and count the files whose rows are not
what was written (the raw file's promise: after a kill, every row read is a row the run wrote).

Each round starts a writer (bench.recorder.Recorder, 100-row blocks of 1 kHz data, flushed each
second of data as in a run), waits until 5 s of data are written, sleeps a seeded random 0 to
--spread s and kills it; the file, read as the bench reads it (RunData: up to each dataset's
`rows_flushed`), must hold t = row x 1 ms and v = 2 t on every row and at least the first 4 s.
The stock view (every row of the dataset's extent, as h5dump shows it) is counted beside it.
Run two at once to load the machine.

Run: .venv/bin/python benchmarks/recorder_kills.py [--rounds 50] [--spread 0.3] [--seed 1]

Measured 2026-11-28 (load ~3, two loops at once, spreads 0.3 s and 0.02 s): 0 bad files of 160.
One suite pass on 4 workers (load 4-7) failed tests/test_recorder.py's kill test once, in the time
column.  Found 2026-11-29 (strace of a flush that opens a chunk): HDF5 writes the chunks, then the
dataset's header with its new extent, then the chunk index, then the superblock; a kill between
the header and the index leaves rows of zeros past the data.  Hence `rows_flushed`, and
tests/test_recorder.py's writer stopped exactly there (a file object that exits at the index's write).
"""

from __future__ import annotations

import argparse
import os
import random
import signal
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

import h5py
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.recorder import open_run  # noqa: E402

WRITER = textwrap.dedent(
    """
    import sys, numpy as np
    from bench.engine import events as ev
    from bench.recorder import Recorder
    rec = Recorder(sys.argv[1], {"params": {"x": 1}})
    k = 0
    while True:
        t = (np.arange(100) + 100 * k) * 1e-3
        rec.on_event(ev.SampleBlock(run_id="r", t_sim_s=float(t[-1]), stream="fpga", columns=("t_s", "v"),
                                    data=np.column_stack([t, t * 2])))
        k += 1
        if k == 50:
            print("ready", flush=True)
    """
)


def one_kill(path: Path, delay_s: float) -> str | None:
    """Kill a writer delay_s after its first 5 s of data; None if the file is as written, else why not."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, "-c", WRITER, str(path)], stdout=subprocess.PIPE, text=True, env=env)
    try:
        if proc.stdout.readline().strip() != "ready":
            return "the writer did not start"
        time.sleep(delay_s)
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.wait(timeout=30)
    with h5py.File(path, "r") as f:
        stock = _wrong(f["streams/fpga"][...])
    with open_run(path) as d:
        bench = _wrong(d.array("fpga"))
    if stock:
        print(f"  the stock view (every row of the extent): {stock}")
    return bench


def _wrong(data: np.ndarray) -> str | None:
    rows = data.shape[0]
    wrong = np.nonzero(~np.isclose(data[:, 0], np.arange(rows) * 1e-3) | ~np.isclose(data[:, 1], 2 * data[:, 0]))[0]
    if rows < 4000:
        return f"{rows} rows, fewer than the 4000 flushed"
    if wrong.size:
        return f"{rows} rows, {wrong.size} not as written from row {wrong[0]} (first: {data[wrong[0]].tolist()})"
    return None


def main() -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--rounds", type=int, default=50)
    p.add_argument("--spread", type=float, default=0.3, help="kill within this many seconds after 'ready'")
    p.add_argument("--seed", type=int, default=1)
    args = p.parse_args()
    rng = random.Random(args.seed)
    bad = 0
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(args.rounds):
            path = Path(tmp) / f"kill{k}.h5"
            why = one_kill(path, rng.uniform(0.0, args.spread))
            if why is not None:
                bad += 1
                print(f"round {k}: {why}")
            path.unlink(missing_ok=True)
    print(f"{bad} of {args.rounds} killed writers left rows not as written (load {os.getloadavg()[0]:.1f})")
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main())
