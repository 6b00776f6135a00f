"""A unit's live progress through a line sequence, from the engine's events (no widgets): which of
the sequence's steps runs, its procedure's current step and the fraction done, so the operator
station can show it per unit or per slot.  `follow(bus)` collects events on the engine's thread;
`drain()` applies them on the GUI thread."""

from __future__ import annotations

import queue
from collections.abc import Callable
from typing import Any

from bench.engine import events as ev

#: the events the progress needs (sample blocks and measurements are not queued)
KINDS = (ev.RunStarted, ev.StepStarted, ev.Progress, ev.RunFinished)
#: run outcomes that end a run before its last step
STOPPED = ("ERROR", "ABORTED")


class UnitProgress:
    """Progress of one unit through `n_steps` sequence steps (one engine run each)."""

    def __init__(self, n_steps: int) -> None:
        self.n_steps = max(1, int(n_steps))
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._unsubscribe: list[Callable[[], None]] = []
        self.reset()

    def reset(self) -> None:
        self.run_k = -1  # the sequence step running (0-based), -1 before the first
        self.procedure = ""
        self.sub_index, self.sub_total, self.sub_fraction = 0, 1, 0.0
        self.title = ""
        self.finished = False

    def follow(self, bus: Any) -> None:
        """Collect `bus`'s progress events (on the publishing thread; call before the run starts)."""
        self._unsubscribe.append(bus.subscribe(lambda e: self._queue.put(e) if isinstance(e, KINDS) else None))

    def detach(self) -> None:
        for u in self._unsubscribe:
            u()
        self._unsubscribe.clear()

    def drain(self) -> bool:
        """Apply the queued events (GUI thread); whether anything changed."""
        changed = False
        while True:
            try:
                self.apply(self._queue.get_nowait())
            except queue.Empty:
                return changed
            changed = True

    def apply(self, event: Any) -> None:
        if isinstance(event, ev.RunStarted):
            self.run_k = min(self.run_k + 1, self.n_steps - 1)
            self.procedure = event.procedure
            self.sub_index, self.sub_total, self.sub_fraction, self.title = 0, max(1, len(event.steps)), 0.0, ""
            self.finished = False
        elif isinstance(event, ev.StepStarted):
            self.sub_index, self.sub_total = event.index, max(1, event.total or self.sub_total)
            self.sub_fraction, self.title = 0.0, event.title or event.name
        elif isinstance(event, ev.Progress):
            self.sub_fraction = min(1.0, max(0.0, float(event.fraction)))
        elif isinstance(event, ev.RunFinished):
            if event.outcome not in STOPPED:  # a run cut short keeps the fraction it reached
                self.sub_index, self.sub_fraction = self.sub_total, 0.0
            self.finished = self.run_k >= self.n_steps - 1

    @property
    def fraction(self) -> float:
        """The unit's fraction done: whole sequence steps, then the running one's engine steps."""
        if self.run_k < 0:
            return 0.0
        within = min(1.0, (self.sub_index + self.sub_fraction) / self.sub_total)
        return min(1.0, (self.run_k + within) / self.n_steps)

    @property
    def text(self) -> str:
        """`step K/N PROCEDURE: TITLE` (the running step's name), or '' before the first."""
        if self.run_k < 0:
            return ""
        head = f"step {self.run_k + 1}/{self.n_steps} {self.procedure}"
        return f"{head}: {self.title}" if self.title and not self.finished else head
