"""Raw file compression, measured on a real run's streams (issue 13, item 7): for no filter and
gzip levels 1, 4 and 6, with and without shuffle, the size of the closed file and the write
throughput of the close-time rewrite (`bench.recorder.compact`), plus the same filter applied
while recording (rejected: see bench/recorder.py) for comparison.  Every file is checked to read
back identical, and with h5dump where installed.

    .venv/bin/python benchmarks/raw_compression.py [RAW.h5]

Without RAW.h5 it records an hrg-damping run on sim-hrg (seed 1, 1108 s bench time) first.
Prints one row per filter; best of 3 timings.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import h5py
import numpy as np

import bench.recorder as br
from bench.engine import events as ev

LEVELS = (None, 1, 4, 6)
REPEATS = 3


def record_a_run(tmp: Path) -> Path:
    cmd = [sys.executable, "-m", "bench.cli", "run", "hrg-damping", "--seed", "1", "--json",
           "--runs-dir", str(tmp / "runs"), "--results", str(tmp / "store.sqlite")]
    out = subprocess.run(cmd, capture_output=True, text=True, check=True)
    return Path(json.loads(out.stdout)["raw_file"])


def uncompressed_copy(src: Path, dst: Path) -> Path:
    """The run's file with its streams as the recorder writes them during a run (no filter)."""
    shutil.copyfile(src, dst)
    if any(ds.compression for ds in h5py.File(src, "r")["streams"].values()):
        br.compact(dst, {}, br.CHUNK_ROWS)
    return dst


def streams_of(path: Path) -> dict[str, tuple[list[str], np.ndarray]]:
    with h5py.File(path, "r") as f:
        return {k: (json.loads(d.attrs["columns"]), d[...]) for k, d in f["streams"].items()}


def events_of(streams: dict[str, tuple[list[str], np.ndarray]]) -> list[ev.SampleBlock]:
    """The streams as 0.1 s blocks in bench-time order, as the bus delivers them in a run."""
    out = []
    for name, (cols, a) in streams.items():
        tcol = cols.index("t_s") if "t_s" in cols else len(cols) - 1
        t = a[:, tcol]
        cuts = np.flatnonzero(np.diff(np.floor(t / 0.1))) + 1
        for idx in np.split(np.arange(len(a)), cuts):
            if len(idx):
                out.append(ev.SampleBlock(run_id="b", t_sim_s=float(t[idx[-1]]), stream=name, columns=tuple(cols),
                                          data=a[idx]))
    return sorted(out, key=lambda e: e.t_sim_s)


def filters(level: int | str | None, shuffle: bool) -> dict:
    if level == "szip":
        return {"compression": "szip", "compression_opts": ("nn", 16), "shuffle": shuffle}
    return {} if level is None else {"compression": "gzip", "compression_opts": level, "shuffle": shuffle}


def check_same(path: Path, streams: dict) -> None:
    got = streams_of(path)
    for name, (_, a) in streams.items():
        np.testing.assert_array_equal(got[name][1], a)
    if shutil.which("h5dump"):  # the stock tool decodes a filtered stream (fails without the filter)
        subprocess.run(["h5dump", "-d", "/streams/table", str(path)], capture_output=True, check=True)


def live_write(evs: list[ev.SampleBlock], path: Path, flt: dict) -> float:
    """Seconds to record the run's blocks with the filter on while recording (flush every second)."""
    original = h5py.Group.create_dataset

    def with_filter(self, name, *args, **kwargs):
        if self.name == "/streams":
            kwargs.update(flt)
        return original(self, name, *args, **kwargs)

    h5py.Group.create_dataset = with_filter
    saved, br.STREAM_FILTERS = br.STREAM_FILTERS, None
    try:
        t0 = time.perf_counter()
        rec = br.Recorder(path)
        for e in evs:
            rec.on_event(e)
        rec.close()
        return time.perf_counter() - t0
    finally:
        h5py.Group.create_dataset = original
        br.STREAM_FILTERS = saved


def main() -> None:
    with tempfile.TemporaryDirectory() as tmpdir:
        tmp = Path(tmpdir)
        src = Path(sys.argv[1]) if len(sys.argv) > 1 else record_a_run(tmp)
        raw = uncompressed_copy(src, tmp / "raw.h5")
        streams = streams_of(raw)
        rows = sum(len(a) for _, a in streams.values())
        mb = sum(a.nbytes for _, a in streams.values()) / 1e6
        size0 = raw.stat().st_size / 1e6
        print(f"{src.name}: {rows} rows, {mb:.1f} MB of stream data, file {size0:.2f} MB as recorded")
        print(f"{'filter':<18} {'size MB':>8} {'ratio':>6} {'close rewrite s':>16} {'MB/s':>6}")
        configs = [(level, shuffle) for level in LEVELS for shuffle in ((False, True) if level else (False,))]
        if h5py.h5z.filter_avail(h5py.h5z.FILTER_SZIP):
            configs.append(("szip", True))
        for level, shuffle in configs:
            flt = filters(level, shuffle)
            times = []
            name = "none" if level is None else (level if level == "szip" else f"gzip {level}")
            name += " +shuffle" if shuffle else ""
            for k in range(REPEATS):
                out = tmp / f"c{k}.h5"
                shutil.copyfile(raw, out)
                t0 = time.perf_counter()
                if not br.compact(out, flt):
                    break
                times.append(time.perf_counter() - t0)
            if not times:
                print(f"{name:<18} fails (szip: a small stream's chunk holds fewer values than a block)")
                continue
            check_same(out, streams)
            size = out.stat().st_size / 1e6
            t = min(times)
            print(f"{name:<18} {size:8.2f} {raw.stat().st_size / 1e6 / size:6.2f} {t:16.2f} {mb / t:6.0f}")
        evs = events_of(streams)
        for flt, name in (({}, "none"), (filters(4, True), "gzip 4 +shuffle")):
            out = tmp / "live.h5"
            t = min(live_write(evs, out, flt) for _ in range(REPEATS))
            check_same(out, streams)
            print(f"filter while recording, {name:<16}: {out.stat().st_size / 1e6:6.2f} MB, {t:5.2f} s "
                  f"for the run's {len(evs)} blocks")


if __name__ == "__main__":
    main()
