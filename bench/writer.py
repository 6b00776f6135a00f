"""Between acquisition and storage.  In real time, a bounded queue and a writer thread: the thread
that publishes a block (the FPGA link's reader, the engine) only queues it, the writer thread hands
it to the recorder, and a block that finds the queue full is dropped, counted and warned about (the
acquisition must not wait for a slow disk).  In lockstep the publishing thread writes the event
itself, in the order published, after anything real time had queued: the strictest backpressure
(the simulation waits for the disk, no block is lost, a failed write is known before the clock
moves on) and no writer thread working beside the run (a quicker run: docs/raw_data.md).  Other
events (log, measurements, steps) are never dropped.  A write that fails goes to `on_error` (the
runner ends the run at its next checkpoint); later events are dropped, so nothing blocks."""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections.abc import Callable
from typing import Any

from bench.engine import events as ev
from bench.engine.context import RunAborted

#: events the queue holds (about a second of a 1 kHz stream in 50 ms blocks, many times over)
QUEUE_EVENTS = 256
log = logging.getLogger("gyrobench.writer")
_STOP = object()


class WriterThread:
    """Feeds `recorder.on_event` from a bounded queue on its own thread; `put` is the bus
    subscriber.  `overflow_blocks` / `overflow_rows` count what real time dropped."""

    def __init__(self, recorder: Any, *, lockstep: bool | Callable[[], bool],
                 on_error: Callable[[BaseException], None], maxsize: int | None = None) -> None:
        self.recorder = recorder
        self._lockstep = lockstep if callable(lockstep) else (lambda: bool(lockstep))  # the GUI may change it
        self.on_error = on_error
        self.overflow_blocks = 0
        self.overflow_rows = 0
        self._q: queue.Queue = queue.Queue(maxsize=maxsize or QUEUE_EVENTS)
        self._queued = 0  # events accepted so far, and events written (or discarded) so far
        self._written = 0
        self._count_lock = threading.Lock()
        self._progress = threading.Condition()
        self._failed = False
        self._closed = False
        self._thread = threading.Thread(target=self._loop, name="raw-data-writer", daemon=True)
        self._thread.start()

    # --- the producer's side ------------------------------------------------------------------
    def put(self, event: ev.Event) -> None:
        """Lockstep: write the event now, on the calling thread.  Real time: queue it (blocks while
        the queue is full, except a stream block, which is then dropped and counted)."""
        if self._closed:
            return
        with self._count_lock:  # in the order published (several producers)
            lockstep = self._lockstep()
            if lockstep and not self._failed:
                if self._written < self._queued:  # queued in real time (the speed just changed): those first
                    self.drain()
                self._write(event)
                return
            if not isinstance(event, ev.SampleBlock) or lockstep:
                self._q.put(event)
                self._queued += 1
                return
            try:
                self._q.put_nowait(event)
                self._queued += 1
                return
            except queue.Full:
                self.overflow_blocks += 1
                self.overflow_rows += len(event.data)
            if self.overflow_blocks == 1:
                log.warning("raw data: the writer cannot keep up; stream %r block at t = %.3f s dropped (and counted)",
                            event.stream, event.t_sim_s)

    def overflow_text(self) -> str:
        return (f"raw data: {self.overflow_blocks} stream block(s) ({self.overflow_rows} rows) dropped in real time: "
                f"the writer could not keep up with the acquisition")

    def _write(self, event: ev.Event) -> None:
        """One event to the recorder; the first failure goes to on_error and later events are dropped."""
        if self._failed:
            return
        try:
            self.recorder.on_event(event)
        except Exception as exc:  # noqa: BLE001 - RawDataError, or any failure: the run ends
            self._failed = True
            self.on_error(exc)

    # --- the writer thread --------------------------------------------------------------------
    def _loop(self) -> None:
        while True:
            event = self._q.get()
            try:
                if event is _STOP:
                    return
                self._write(event)
            finally:
                with self._progress:
                    self._written += 1
                    self._progress.notify_all()

    def drain(self, timeout_s: float = 60.0) -> None:
        """Wait (wall time) until every event queued before this call is written (events queued
        meanwhile need not be: a stream in real time never stops); RunAborted if the writer does
        not get there within timeout_s (a disk that hangs)."""
        deadline = time.monotonic() + timeout_s
        target = self._queued
        with self._progress:
            while self._written < target:
                left = deadline - time.monotonic()
                if left <= 0:
                    raise RunAborted(f"raw data: the writer has not caught up within {timeout_s:g} s "
                                     f"({target - self._written} events still queued)")
                self._progress.wait(min(left, 0.1))

    def close(self, timeout_s: float = 60.0) -> None:
        """Write what is queued, then end the thread."""
        if self._closed:
            return
        self._closed = True
        self._q.put(_STOP)
        self._thread.join(timeout_s)
        if self._thread.is_alive():
            log.error("raw data: the writer thread did not end within %g s", timeout_s)

    def data(self) -> Any:
        """What the recorder holds, after every event queued so far is written."""
        self.drain()
        return self.recorder.data()
