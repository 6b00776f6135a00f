"""Engine events -> the Qt thread.

`EventBus.publish` calls subscribers in the engine's thread; a widget touched there crashes Qt
sooner or later (bluesky#1222).  The bridge only queues the event and, when the queue was
empty, emits a queued signal; the GUI thread then drains the whole queue at once.  However fast
the engine runs, the event loop receives at most one wake-up per drain, so it cannot be flooded.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable

from PySide6.QtCore import QObject, Qt, Signal

from bench.engine.events import Event, EventBus


class EventBridge(QObject):
    """Subscribes to a bus; emits `events(list)` in the GUI thread with everything queued since."""

    events = Signal(list)
    _wake = Signal()

    def __init__(self, bus: EventBus | None = None, parent: QObject | None = None) -> None:
        super().__init__(parent)
        self._queue: deque[Event] = deque()
        self._lock = threading.Lock()
        self._pending = False
        self._unsubscribe: Callable[[], None] | None = None
        self._gate: Callable[[Event], None] | None = None
        self.delivered = 0
        self.latency_s: deque[float] = deque(maxlen=10_000)  # publish -> GUI thread, wall seconds
        self._wake.connect(self._drain, Qt.ConnectionType.QueuedConnection)
        if bus is not None:
            self.attach(bus)

    def attach(self, bus: EventBus) -> None:
        self.detach()
        self._unsubscribe = bus.subscribe(self.post)

    def detach(self) -> None:
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
            self._queue.append(event)
            wake = not self._pending
            self._pending = True
        if wake:
            self._wake.emit()
        gate = self._gate
        if gate is not None:
            gate(event)

    def drain(self) -> None:
        """GUI thread: deliver what is queued now (tests call it to avoid waiting)."""
        self._drain()

    def _drain(self) -> None:
        with self._lock:
            batch = list(self._queue)
            self._queue.clear()
            self._pending = False
        if not batch:
            return
        now = time.time()
        self.latency_s.append(now - batch[0].t_wall)
        self.delivered += len(batch)
        self.events.emit(batch)
