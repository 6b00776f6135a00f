"""The bounded queue and writer thread between acquisition and storage (bench.writer): in
lockstep a slow disk slows the simulation and loses no frame; in real time what the writer cannot
take is dropped, counted in the record and the raw file, and warned about; a failing write still
ends the run."""

from __future__ import annotations

import time

import numpy as np
import pytest

import bench.writer as bw
from bench.engine import Runner
from bench.engine import events as ev
from bench.recorder import Recorder, open_run
from procedures.examples.table_spin import TableSpin


def _block(k: int) -> ev.SampleBlock:
    return ev.SampleBlock(run_id="r", t_sim_s=float(k), stream="s", columns=("k",), data=np.array([[float(k)]]))


class SlowSink:
    def __init__(self, delay_s: float) -> None:
        self.delay_s, self.seen = delay_s, []

    def on_event(self, event) -> None:
        time.sleep(self.delay_s)
        self.seen.append(event)


@pytest.mark.parametrize("lockstep", [True, False])
def test_queue_blocks_in_lockstep_and_counts_what_real_time_drops(lockstep, caplog):
    sink = SlowSink(0.002)
    w = bw.WriterThread(sink, lockstep=lockstep, on_error=pytest.fail, maxsize=4)
    for k in range(100):
        w.put(_block(k))
    w.put(ev.Log(run_id="r", t_sim_s=100.0, message="never dropped"))
    w.close()
    ks = [int(e.data[0, 0]) for e in sink.seen if isinstance(e, ev.SampleBlock)]
    assert ks == sorted(ks) and isinstance(sink.seen[-1], ev.Log)
    assert len(ks) + w.overflow_blocks == 100 and w.overflow_rows == w.overflow_blocks
    if lockstep:
        assert w.overflow_blocks == 0
    else:
        assert w.overflow_blocks > 50
        assert "cannot keep up" in caplog.text


def test_a_failing_write_goes_to_on_error_once_and_nothing_blocks():
    errors = []

    class Failing:
        def on_event(self, event):
            raise OSError("disk full")

    w = bw.WriterThread(Failing(), lockstep=True, on_error=errors.append, maxsize=2)
    for k in range(20):
        w.put(_block(k))
    w.drain(timeout_s=5.0)
    w.close()
    assert [str(e) for e in errors] == ["disk full"]


def test_keep_up_waits_only_for_a_writer_more_than_max_lag_behind():
    """Lockstep's bound on how far the simulation runs ahead of the disk (bench.writer.MAX_LAG_S):
    keep_up returns at once while the writer is within the lag, and waits until everything queued
    is written once it is further behind."""
    sink = SlowSink(0.02)
    w = bw.WriterThread(sink, lockstep=True, on_error=pytest.fail)
    try:
        for k in range(20):  # events at t = 0 .. 19 s, each 20 ms to write
            w.put(_block(k))
        t0 = time.perf_counter()
        w.keep_up(now_s=0.5)  # the clock is not a second ahead of anything queued: no wait
        assert time.perf_counter() - t0 < 0.01 and len(sink.seen) < 20
        w.keep_up(now_s=19.0)  # far behind: written up to the last queued event
        assert len(sink.seen) == 20
        w.keep_up(now_s=1000.0)  # nothing queued: nothing to wait for
    finally:
        w.close()


def _spin(tmp_path, monkeypatch, speed: float | None, delay_s: float):
    from bench.station import SimStation

    monkeypatch.setattr(bw, "QUEUE_EVENTS", 2)
    real = Recorder.on_event

    def slow(self, event):
        if isinstance(event, ev.SampleBlock) and event.stream == "fpga":
            time.sleep(delay_s)
        return real(self, event)

    monkeypatch.setattr(Recorder, "on_event", slow)
    station = SimStation("sim-hrg", seed=0, speed=speed).open()
    try:
        link = station.devices["fpga"]
        frames0 = link.stats.frames
        rec = Runner(station, runs_dir=tmp_path).run(TableSpin, {"hold_s": 1.0, "rate_dps": 20.0})
        frames = link.stats.frames - frames0
        assert link.stats.dropped == 0
    finally:
        station.close()
    return rec, frames


def test_lockstep_with_a_slow_disk_loses_no_frame(tmp_path, monkeypatch):
    rec, frames = _spin(tmp_path, monkeypatch, None, 0.001)
    assert rec.outcome == "PASS" and rec.stream_overflow_blocks == 0, rec.end_reason
    with open_run(rec.raw_file) as d:
        index = d.table("fpga")["index"]
        assert len(index) == frames > 100
        assert np.all(np.diff(index) == np.diff(index)[0])  # no gap
        assert d.attrs["stream_overflow_blocks"] == 0


def test_real_time_overflow_is_counted_in_the_record_and_the_file(tmp_path, monkeypatch):
    rec, frames = _spin(tmp_path, monkeypatch, 4.0, 0.05)
    assert rec.stream_overflow_blocks > 0, rec.end_reason
    with open_run(rec.raw_file) as d:
        assert 0 < len(d.table("fpga")["index"]) < frames
        assert d.attrs["stream_overflow_blocks"] == rec.stream_overflow_blocks
        warn = [r for r in d.log() if r["level"] == "WARNING" and "dropped in real time" in r["msg"]]
        assert len(warn) == 1 and f"{rec.stream_overflow_blocks} stream block(s)" in warn[0]["msg"]


def test_drain_waits_for_what_was_queued_before_it_even_while_real_time_keeps_coming():
    import threading

    sink = SlowSink(0.005)
    w = bw.WriterThread(sink, lockstep=False, on_error=pytest.fail, maxsize=8)
    stop = threading.Event()

    def produce() -> None:
        k = 0
        while not stop.is_set():
            w.put(_block(k))
            k += 1
            time.sleep(0)

    w.put(ev.Log(run_id="r", t_sim_s=0.0, message="marker"))
    producer = threading.Thread(target=produce)
    producer.start()
    try:
        w.drain(timeout_s=5.0)  # returns although the queue never empties
        assert any(isinstance(e, ev.Log) for e in sink.seen)
    finally:
        stop.set()
        producer.join()
        w.close()
    assert w.overflow_blocks > 0
