"""Engine events -> the Qt thread.

`EventBus.publish` calls subscribers in the engine's thread; a widget touched there crashes Qt
sooner or later (bluesky#1222).  The bridge only queues the event and, when the queue was
empty, emits a queued signal; the GUI thread then drains the whole queue at once.  However fast
the engine runs, the event loop receives at most one wake-up per drain, so it cannot be flooded;
a drain hands over at most `slice_s` of work and re-posts itself for the rest, so timers and
input keep running while a backlog is worked off.

Backpressure is opt-in (`max_wait_s` > 0), for a simulated station in lockstep only: when more
than `max_pending` events wait, the publisher is held (at most `max_wait_s` per event) so a run
at "max" speed goes at the pace the window can draw instead of queueing without bound.  Never on
real time or a real bench: there a held link reader would lose frames, so the queue just grows
until the window catches up.

Coalescing is opt-in too (`min_gap_s` > 0, the window at "max"): a wake-up within `min_gap_s` of
the last drain is put off until then, so each drain carries more events and the engine's thread
gives the interpreter to the GUI thread less often; a queue half way to `max_pending` is drained at
once (the publisher is never held for the gap).
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable

from PySide6.QtCore import QObject, Qt, QTimer, Signal

from bench.engine.events import Event, EventBus


class EventBridge(QObject):
    """Subscribes to a bus; emits `events(list)` in the GUI thread with everything queued since."""

    events = Signal(list)
    _wake = Signal()

    def __init__(self, bus: EventBus | None = None, parent: QObject | None = None, *, slice_s: float = 0.02,
                 max_pending: int = 50, max_wait_s: float = 0.0, min_gap_s: float = 0.0) -> None:
        super().__init__(parent)
        self._queue: deque[Event] = deque()
        self._lock = threading.Lock()
        self._drained = threading.Condition(self._lock)
        self.slice_s = slice_s
        self.max_pending = max_pending
        self.max_wait_s = max_wait_s
        self._pending = False
        self._unsubscribe: Callable[[], None] | None = None
        self._gate: Callable[[Event], None] | None = None
        self.delivered = 0
        self.held_s = 0.0  # wall seconds the publisher was held by the backpressure (benchmarks/gui_max_speed.py)
        self.latency_s: deque[float] = deque(maxlen=10_000)  # publish -> GUI thread, wall seconds
        self.min_gap_s = min_gap_s
        self._last_drain = -1e300  # perf_counter of the last drain's start
        self._later = QTimer(self)  # a drain put off by min_gap_s
        self._later.setSingleShot(True)
        self._later.timeout.connect(self._drain)
        self._wake.connect(self._on_wake, Qt.ConnectionType.QueuedConnection)
        if bus is not None:
            self.attach(bus)

    def attach(self, bus: EventBus) -> None:
        self.detach()
        self._unsubscribe = bus.subscribe(self.post)

    def detach(self) -> None:
        """Stop taking events and drop a put-off drain (GUI thread: the timer is this thread's)."""
        self._later.stop()
        if self._unsubscribe is not None:
            self._unsubscribe()
            self._unsubscribe = None

    def set_gate(self, gate: Callable[[Event], None] | None) -> None:
        """A callable run in the publishing thread before queueing (the screenshot mode uses it
        to hold the engine at a chosen simulated second)."""
        self._gate = gate

    def post(self, event: Event) -> None:
        """Any thread: queue the event and wake the GUI thread if it is not already woken."""
        with self._lock:
            if (self.max_wait_s > 0 and len(self._queue) >= self.max_pending
                    and threading.current_thread() is not threading.main_thread()):
                t_held = time.perf_counter()
                self._drained.wait_for(lambda: len(self._queue) < self.max_pending, self.max_wait_s)
                self.held_s += time.perf_counter() - t_held
            self._queue.append(event)
            # woken once per drain; with coalescing once more when the queue is half full (at once)
            wake = not self._pending or (self.min_gap_s > 0 and len(self._queue) == max(1, self.max_pending // 2))
            self._pending = True
        if wake:
            self._wake.emit()
        gate = self._gate
        if gate is not None:
            gate(event)

    def drain(self) -> None:
        """GUI thread: deliver everything queued now (the screenshot mode calls it)."""
        while True:
            with self._lock:
                if not self._queue:
                    return
            self._drain()

    def _on_wake(self) -> None:
        """GUI thread: drain now, or (coalescing) when min_gap_s has passed since the last drain."""
        if self.min_gap_s > 0:
            wait_s = self._last_drain + self.min_gap_s - time.perf_counter()
            with self._lock:
                full = len(self._queue) >= max(1, self.max_pending // 2)
            if wait_s > 0 and not full:
                if not self._later.isActive():
                    self._later.start(max(1, int(wait_s * 1000.0 + 0.5)))
                return
        self._later.stop()
        self._drain()

    def _drain(self) -> None:
        self._last_drain = time.perf_counter()
        t_end = self._last_drain + self.slice_s
        while True:
            with self._lock:
                batch = [self._queue.popleft() for _ in range(min(len(self._queue), 200))]
                self._drained.notify_all()
                if not batch:
                    self._pending = False
                    return
            self.latency_s.append(time.time() - batch[0].t_wall)
            self.delivered += len(batch)
            self.events.emit(batch)
            if time.perf_counter() > t_end:
                with self._lock:
                    more = bool(self._queue)
                    self._pending = more
                if more:
                    self._wake.emit()  # the rest after the event loop has had its turn
                return
