"""The driver side of the table's watchdog: a daemon thread that feeds it on the wall clock.

Why wall time: the table measures its watchdog on its own (wall) clock, because a real
controller does and because the bench's virtual time can run ~1000x faster than wall time in
lockstep (a virtual-time heartbeat would then starve in real time and flood in lockstep).  Every
command also feeds the watchdog, so the thread only writes when the driver has been silent for a
period.  A bench process that dies takes the thread with it and the table stops itself.  In
lockstep a loaded machine can starve this thread for seconds: the simulated table then counts
the station's reads at every grid point as signs of life in simulated time (docs/rate_table_modbus.md).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable


class Heartbeat:
    """Calls `feed()` every `period_s` of wall time in which no other write went out."""

    def __init__(self, feed: Callable[[], None], period_s: float, name: str = "table-heartbeat") -> None:
        if not period_s > 0:
            raise ValueError(f"heartbeat period_s={period_s!r} must be > 0")
        self._feed, self.period_s, self._name = feed, float(period_s), name
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.last_write_wall = time.monotonic()
        self.last_error: BaseException | None = None
        self.beats = 0

    def note_write(self) -> None:
        """A command went out: it fed the watchdog too."""
        self.last_write_wall = time.monotonic()

    def start(self) -> None:
        if self._thread is None:
            self._stop.clear()
            self._thread = threading.Thread(target=self._run, name=self._name, daemon=True)
            self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def _run(self) -> None:
        while not self._stop.wait(self.period_s / 2.0):
            if time.monotonic() - self.last_write_wall < self.period_s:
                continue
            try:
                self._feed()
                self.beats += 1
                self.last_error = None
            except Exception as exc:  # the next beat retries; the procedure sees link errors itself
                self.last_error = exc
            self.last_write_wall = time.monotonic()
