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


def test_lockstep_writes_on_the_publishing_thread_after_what_real_time_queued():
    """Lockstep: put returns once the event is written, written by the thread that published it;
    events real time had queued (the window's speed control switched to lockstep) are written
    first, so the file keeps the order published."""
    import threading

    class Sink(SlowSink):
        def on_event(self, event) -> None:
            super().on_event(event)
            self.threads = getattr(self, "threads", []) + [threading.current_thread().name]

    sink = Sink(0.01)
    mode = {"lockstep": False}
    w = bw.WriterThread(sink, lockstep=lambda: mode["lockstep"], on_error=pytest.fail)
    try:
        for k in range(5):  # real time: queued, the writer thread writes them (10 ms each)
            w.put(_block(k))
        mode["lockstep"] = True
        for k in range(5, 10):
            w.put(_block(k))
            assert int(sink.seen[-1].data[0, 0]) == k  # written before put returned
        assert [int(e.data[0, 0]) for e in sink.seen] == list(range(10))
        assert sink.threads[5:] == [threading.current_thread().name] * 5
        assert set(sink.threads[:5]) <= {"raw-data-writer", threading.current_thread().name}
    finally:
        w.close()


def _spin(tmp_path, monkeypatch, speed: float | None, delay_s: float):
    from bench.composition.sim_station import SimStation

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
        # the producer outruns the 5 ms sink: the full queue drops blocks sooner or later (on a loaded
        # machine the producer thread may not have had its turn yet when the drain returned)
        deadline = time.monotonic() + 30.0
        while w.overflow_blocks == 0 and time.monotonic() < deadline:
            time.sleep(0.01)
    finally:
        stop.set()
        producer.join()
        w.close()
    assert w.overflow_blocks > 0
