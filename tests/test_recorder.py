"""The recorder: streams, log and measurements to HDF5; flushed each second of data, so a
SIGKILLed writer leaves a readable file."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import textwrap
import time

import h5py
import numpy as np
import pytest

from bench.engine import events as ev
from bench.recorder import ROWS_FLUSHED, Recorder, open_run


def test_streams_log_measurements_roundtrip(tmp_path):
    rec = Recorder(tmp_path / "r.h5", {"params": {"rate_dps": 10.0}, "procedure": "x", "truth": {"tau_s": 2.0}})
    for k in range(5):
        t = np.arange(k * 100, (k + 1) * 100) * 1e-3
        rec.on_event(
            ev.SampleBlock(
                run_id="r", t_sim_s=t[-1], stream="fpga", columns=("t_s", "cx"), data=np.column_stack([t, np.sin(t)])
            )
        )
    rec.on_event(ev.Measurement(run_id="r", t_sim_s=0.5, name="tau_s", value=2.1, unit="s", outcome="COMPLETE"))
    rec.on_event(ev.Log(run_id="r", t_sim_s=0.5, message="hello"))
    rec.on_event(ev.FitUpdate(run_id="r", t_sim_s=0.5, name="decay", curves={"t_s": np.arange(3.0)}))
    mid = rec.data()
    assert mid.table("fpga")["t_s"].shape == (500,)
    rec.close()
    with open_run(tmp_path / "r.h5") as d:
        assert d.params == {"rate_dps": 10.0} and d.truth == {"tau_s": 2.0}
        tab = d.table("fpga")
        np.testing.assert_array_equal(tab["cx"], np.sin(np.arange(500) * 1e-3))
        assert d.measurements()[0]["name"] == "tau_s" and d.log()[0]["msg"] == "hello"
        np.testing.assert_array_equal(d.fits()["decay"]["t_s"], np.arange(3.0))


def test_column_mismatch_is_an_error(tmp_path):
    rec = Recorder(tmp_path / "r.h5")
    rec.append("s", ("a", "b"), np.zeros((2, 2)))
    with pytest.raises(ValueError, match="3 columns"):
        rec.append("s", ("a", "b", "c"), np.zeros((2, 3)))
    rec.close()


_WRITER = textwrap.dedent(
    """
    import sys, numpy as np
    from bench.engine import events as ev
    from bench.recorder import Recorder
    rec = Recorder(sys.argv[1], {"params": {"x": 1}})
    k = 0
    while True:
        t = (np.arange(100) + 100 * k) * 1e-3   # 0.1 s of 1 kHz data a block
        rec.on_event(ev.SampleBlock(run_id="r", t_sim_s=float(t[-1]), stream="fpga", columns=("t_s", "v"),
                                    data=np.column_stack([t, t * 2])))
        k += 1
        if k == 50:
            print("ready", flush=True)
    """
)


def test_sigkilled_writer_leaves_a_readable_file(tmp_path):
    path = tmp_path / "killed.h5"
    proc = subprocess.Popen([sys.executable, "-c", _WRITER, str(path)], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "ready"  # 5 s of data written
        time.sleep(0.3)
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.wait(timeout=30)
    assert proc.returncode == -signal.SIGKILL
    with h5py.File(path, "r") as f:  # a stock reader opens it; the rows that are data are counted
        ds = f["streams/fpga"]
        assert 0 < ds.attrs[ROWS_FLUSHED] <= ds.shape[0]
    with open_run(path) as d:  # and the bench's reader reads exactly those
        data = d.array("fpga")
    # flushed every second of data: at least the first 4 s of the 5 s written before "ready"
    assert data.shape[0] >= 4000
    np.testing.assert_allclose(data[:, 0], np.arange(data.shape[0]) * 1e-3)
    np.testing.assert_allclose(data[:, 1], 2 * data[:, 0])


# HDF5 writes a flush's metadata in turn: the dataset's header (its new extent), then the chunk
# index, then the superblock.  This writer's file object ends the process at the chunk index's
# write of a flush that opens a new chunk: a SIGKILL between those two writes, made certain.
_TORN = textwrap.dedent(
    """
    import io, os, sys
    import h5py, numpy as np
    from bench.recorder import Recorder
    armed = False
    class Torn(io.FileIO):
        def write(self, b):
            if armed and bytes(b[:4]) == b"TREE":  # a v1 B-tree node: the chunk index
                os._exit(9)
            return super().write(b)
    h5_file = h5py.File
    h5py.File = lambda name, mode="r", **kw: h5_file(Torn(name, "w+") if mode == "w" else name, mode, **kw)
    rec = Recorder(sys.argv[1], {"params": {"x": 1}})
    t = np.arange(5000) * 1e-3
    rec.append("fpga", ("t_s", "v"), np.column_stack([t, 2 * t])[:4000])
    rec.on_event(__import__("bench.engine.events", fromlist=["Log"]).Log(run_id="r", t_sim_s=4.0, message="4 s"))
    rec.flush()
    armed = True
    rec.append("fpga", ("t_s", "v"), np.column_stack([t, 2 * t])[4000:])  # rows 4096.. open chunk 2
    rec.flush()
    print("the flush was not torn")
    """
)


def test_a_writer_killed_mid_flush_leaves_no_row_it_did_not_write(tmp_path):
    path = tmp_path / "torn.h5"
    proc = subprocess.run([sys.executable, "-c", _TORN, str(path)], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 9, proc.stdout + proc.stderr[-2000:]
    with h5py.File(path, "r") as f:  # the stock view: the extent of 5000 rows reached the disk, its index did not
        ds = f["streams/fpga"]
        assert ds.shape[0] == 5000 and ds.attrs[ROWS_FLUSHED] == 4000
        assert not ds[4096:, 0].any()  # rows the writer never wrote: HDF5's fill value
    with open_run(path) as d:
        data = d.array("fpga")
        np.testing.assert_array_equal(data[:, 0], np.arange(4000) * 1e-3)  # every row as written, none more
        np.testing.assert_array_equal(data[:, 1], 2 * data[:, 0])
        assert [r["msg"] for r in d.log()] == ["4 s"]
        assert any("fpga: its last 1000 of 5000 rows are past the last flush that completed" in n for n in d.notes)
        assert d.incomplete.startswith("the run did not finish")
    from bench.gui.replay import replay_events  # the window's replay reads the same rows

    replayed = [e for e in replay_events(path) if isinstance(e, ev.SampleBlock) and e.stream == "fpga"]
    np.testing.assert_array_equal(np.concatenate([e.data for e in replayed])[:, 0], np.arange(4000) * 1e-3)


def test_a_closed_file_counts_every_row_as_flushed(tmp_path):
    rec = Recorder(tmp_path / "r.h5", {"params": {"x": 1}})
    for k in range(30):  # across chunks, with flushes between
        t = (np.arange(500) + 500 * k) * 1e-3
        rec.on_event(ev.SampleBlock(run_id="r", t_sim_s=float(t[-1]), stream="fpga", columns=("t_s", "v"),
                                    data=np.column_stack([t, t])))
        rec.on_event(ev.Log(run_id="r", t_sim_s=float(t[-1]), message=f"block {k}"))
    rec.close()  # compressed into a new file: the counts go with the datasets
    with h5py.File(tmp_path / "r.h5", "r") as f:
        for name in ("streams/fpga", "log", "measurements"):
            assert f[name].attrs[ROWS_FLUSHED] == f[name].shape[0], name
        assert f["streams/fpga"].shape[0] == 15000 and f["streams/fpga"].compression == "gzip"
    with open_run(tmp_path / "r.h5") as d:
        assert d.array("fpga").shape == (15000, 2) and len(d.log()) == 30 and not d.notes


# --- a disk that fills (issue 13, item 1) --------------------------------------------------------
_FILLER = textwrap.dedent(
    """
    import resource, signal, sys, numpy as np
    import bench.recorder as br
    from bench.engine import events as ev
    if sys.argv[2] == "rlimit":  # every write past 1.5 MB fails (EFBIG), as on a full disk
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (1_500_000, resource.RLIM_INFINITY))
        br.Recorder._take_reserve = lambda self: None
        # freeing the reserve makes room again
        br.Recorder._drop_reserve = lambda self: resource.setrlimit(resource.RLIMIT_FSIZE, (-1, -1))
    br.Recorder._check_space = lambda self: None  # let the write itself fail inside HDF5
    rec = br.Recorder(sys.argv[1], {"params": {"x": 1}})
    k = 0
    try:
        while True:
            t = (np.arange(100) + 100 * k) * 1e-3
            rec.on_event(ev.SampleBlock(run_id="r", t_sim_s=float(t[-1]), stream="fpga", columns=("t_s", "v"),
                                        data=np.column_stack([t, t * 2])))
            if k % 5 == 0:
                rec.on_event(ev.SampleBlock(run_id="r", t_sim_s=float(t[-1]), stream="table",
                                            columns=("t_s", "rate_dps"), data=np.array([[t[-1], 1.0]])))
            k += 1
    except br.RawDataError as exc:
        print(exc, flush=True)
    rec.on_event(ev.Log(run_id="r", t_sim_s=99.0, message="after the failure: ignored"))
    rec.close()
    """
)


def _tmpfs(path, size: str) -> bool:
    """A tmpfs of `size` at path (root only); False where that is not possible (not root, or a
    container without the right to mount: the file-size-limit test covers the failing write)."""
    if os.geteuid() != 0:
        return False
    path.mkdir(exist_ok=True)
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(path)], capture_output=True)
    return done.returncode == 0


def _assert_cut_at_a_flush(path, message: str) -> None:
    """The file reads back (h5py, and h5dump where installed) with every row written up to the
    last flush before the failure, and names the failure in its log."""
    assert message.startswith("raw data: ") and " at t = " in message and str(path) in message
    kept_s = float(message.split("the data up to t = ")[1].split(" s")[0])
    with open_run(path) as d:
        t = d.table("fpga")["t_s"]
        np.testing.assert_allclose(t, np.arange(len(t)) * 1e-3)  # no hole, no zeros, no foreign rows
        np.testing.assert_allclose(d.table("fpga")["v"], 2 * t)
        assert len(t) > 10000 and t[-1] == pytest.approx(kept_s, abs=0.051)
        assert d.log()[-1]["level"] == "ERROR" and d.log()[-1]["msg"] == message
    if shutil.which("h5dump"):
        assert subprocess.run(["h5dump", "-H", str(path)], capture_output=True).returncode == 0


def test_a_write_that_fails_keeps_the_flushed_data_and_closes_cleanly(tmp_path):
    """Writes failing inside HDF5 (here: a file size limit, no root needed) leave HDF5's state
    unusable; the recorder reopens the file from disk, cuts it back to the last flush and exits
    cleanly (it used to end in a segmentation fault at exit, the last second holding zeros)."""
    path = tmp_path / "full.h5"
    done = subprocess.run([sys.executable, "-c", _FILLER, str(path), "rlimit"], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    message = done.stdout.strip()
    assert message.startswith("raw data: write failed at t = ") and "(File too large)" in message, message
    _assert_cut_at_a_flush(path, message)


@pytest.mark.parametrize("check_space", [True, False])
def test_a_full_tmpfs_keeps_the_flushed_data_and_closes_cleanly(tmp_path, check_space):
    """On a real full disk (a 3 MB tmpfs): declared full while 1 MiB is still free, or (no space
    check) when HDF5's own write fails with ENOSPC."""
    mnt = tmp_path / "mnt"
    if not _tmpfs(mnt, "3m"):
        pytest.skip("a tmpfs needs root; the file-size limit test covers the failing write")
    try:
        path = mnt / "full.h5"
        script = _FILLER if not check_space else _FILLER.replace("br.Recorder._check_space = ", "_ = ")
        done = subprocess.run([sys.executable, "-c", script, str(path), "tmpfs"], capture_output=True, text=True,
                              timeout=120)
        assert done.returncode == 0, done.stderr[-2000:]
        message = done.stdout.strip()
        assert message.startswith("raw data: disk full at t = "), message
        if check_space:
            assert f"MB free on {mnt}, the recorder stops below 1.05 MB" in message
        _assert_cut_at_a_flush(path, message)
        assert [p.name for p in mnt.iterdir()] == ["full.h5"]  # the reserve is gone
    finally:
        subprocess.run(["umount", str(mnt)], check=False)


def test_the_closed_file_has_its_streams_compressed_and_reads_back_the_same(tmp_path):
    """Issue 13, item 7: gzip (the stock tools read it), applied when the file is
    closed; while the run goes on the streams stay uncompressed (a killed run's file stays readable)."""
    rng = np.random.default_rng(7)
    t = np.arange(20000) * 1e-3
    sig = np.column_stack([t, np.exp(-t / 300) * np.cos(t), 1e-3 * rng.normal(size=t.size)])
    rec = Recorder(tmp_path / "c.h5", {"params": {"x": 1}})
    for k in range(0, len(t), 100):
        rec.on_event(ev.SampleBlock(run_id="r", t_sim_s=t[k + 99], stream="fpga", columns=("t_s", "c", "n"),
                                    data=sig[k : k + 100]))
    rec.on_event(ev.Log(run_id="r", t_sim_s=20.0, message="end"))
    rec.on_event(ev.FitUpdate(run_id="r", t_sim_s=20.0, name="decay", curves={"t_s": np.arange(3.0)}))
    assert rec.data().f["streams/fpga"].compression is None  # as written during the run
    rec.close()
    assert [p.name for p in tmp_path.iterdir()] == ["c.h5"]  # no reserve, no temporary file left
    with h5py.File(tmp_path / "c.h5", "r") as f:
        ds = f["streams/fpga"]
        assert ds.compression == "gzip" and not ds.shuffle and ds.compression_opts == 1
        assert f["streams/fpga"].id.get_storage_size() < 0.9 * sig.nbytes  # noise compresses little
    with open_run(tmp_path / "c.h5") as d:
        np.testing.assert_array_equal(d.array("fpga"), sig)
        assert d.params == {"x": 1} and d.log()[-1]["msg"] == "end" and d.columns("fpga") == ["t_s", "c", "n"]
        np.testing.assert_array_equal(d.fits()["decay"]["t_s"], np.arange(3.0))
    if shutil.which("h5dump"):
        assert subprocess.run(["h5dump", str(tmp_path / "c.h5")], capture_output=True).returncode == 0


@pytest.mark.parametrize("case", ["file", "under-a-file"])
def test_a_runs_dir_that_cannot_hold_files_ends_the_run_before_its_first_step(tmp_path, case):
    """The raw file cannot be created: the run ends ERROR at its first checkpoint, in the safe
    state, with one message naming the path (it used to be a FileExistsError traceback)."""
    from bench.composition.sim_station import SimStation
    from bench.engine import Runner
    from procedures.examples.table_spin import TableSpin

    blocker = tmp_path / "runs"
    blocker.write_text("a file")
    runs_dir = blocker if case == "file" else blocker / "deeper"
    station = SimStation("sim-hrg", seed=0).open()
    try:
        rec = Runner(station, runs_dir=runs_dir).run(TableSpin, {"hold_s": 0.5})
    finally:
        station.close()
    assert rec.outcome == "ERROR" and rec.safe_state and rec.raw_file is None
    assert rec.end_reason == f"raw data: cannot create {blocker}: it is a file, not a directory"
    assert rec.failed_step == "spin_up" and rec.simulated_s < 0.5 and rec.traceback is None


def test_leftovers_of_a_killed_recorder_are_removed_by_the_next(tmp_path):
    """A SIGKILLed run leaves its space reserve (and perhaps a half-written compressed copy); the
    next recorder in that directory removes those whose process is gone, and no other."""
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    dead_pid = int(dead.stdout)
    stale = [tmp_path / f".a.h5.reserve-{dead_pid}", tmp_path / f".a.h5.compact-{dead_pid}"]
    live = tmp_path / f".b.h5.reserve-{os.getpid()}"
    for p in (*stale, live):
        p.write_bytes(b"x")
    rec = Recorder(tmp_path / "c.h5")
    assert not any(p.exists() for p in stale) and live.exists()
    rec.close()
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([live.name, "c.h5"])


def _written(path) -> tuple[Recorder, np.ndarray]:
    """A recorder with 2,000 rows of a stream, not yet closed."""
    sig = np.column_stack([np.arange(2000) * 1e-3, np.cos(np.arange(2000) * 1e-2)])
    rec = Recorder(path)
    rec.on_event(ev.SampleBlock(run_id="r", t_sim_s=2.0, stream="fpga", columns=("t_s", "c"), data=sig))
    return rec, sig


def test_a_deferred_compaction_leaves_the_complete_file_and_a_background_process_compresses_it(tmp_path):
    """`gyrobench run` returns before the compression (issue 36): the file as closed is complete
    and readable; `python -m bench.compaction` (detached) then replaces it with the compressed one."""
    from bench.recorder import compact_in_background

    rec, sig = _written(tmp_path / "d.h5")
    rec.defer_compaction = True
    rec.close()
    assert rec.compaction_pending
    with open_run(tmp_path / "d.h5") as d:
        assert d.f["streams/fpga"].compression is None
        np.testing.assert_array_equal(d.array("fpga"), sig)
    assert compact_in_background(tmp_path / "d.h5").wait(timeout=120) == 0
    assert [p.name for p in tmp_path.iterdir()] == ["d.h5"]
    with open_run(tmp_path / "d.h5") as d:
        assert d.f["streams/fpga"].compression == "gzip"
        np.testing.assert_array_equal(d.array("fpga"), sig)


def test_a_file_written_while_it_is_compressed_stays_as_written(tmp_path, monkeypatch):
    """An annotation written during the compaction (another process) is not lost: the compressed
    copy is dropped and the file stays as it was written."""
    import bench.recorder as recorder_module

    rec, sig = _written(tmp_path / "e.h5")
    rec.defer_compaction = True
    rec.close()
    stamps = iter([(1, 1, 1), (1, 1, 2)])  # the file's stamp before and after the copy: it changed
    monkeypatch.setattr(recorder_module, "_stamp", lambda path: next(stamps))
    assert recorder_module.compact(tmp_path / "e.h5", recorder_module.STREAM_FILTERS) is False
    assert [p.name for p in tmp_path.iterdir()] == ["e.h5"]
    with open_run(tmp_path / "e.h5") as d:
        assert d.f["streams/fpga"].compression is None
        np.testing.assert_array_equal(d.array("fpga"), sig)
