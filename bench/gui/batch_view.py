"""The window's view of a batch (several gyros on one table): one column a slot with its unit,
its outcome, its current step and its live E(t) from its own FPGA stream.

Each slot's runner publishes on its own event bus from its slot thread; the view queues what it
needs there and draws it on the GUI thread (a QTimer), so a slot never waits for the window."""

from __future__ import annotations

import queue
from typing import Any

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import Qt, QTimer
from PySide6.QtWidgets import QHBoxLayout, QLabel, QVBoxLayout, QWidget

from bench.analysis.slow_model import orbit_elements
from bench.engine import events as ev

#: the outcome label's colours (background), as the operator view's verdicts
COLOURS = {"PASS": "#2e7d32", "COMPLETE": "#2e7d32", "MARGINAL": "#f9a825", "FAIL": "#c62828",
           "ERROR": "#1565c0", "ABORTED": "#6a1b9a", "RUNNING": "#546e7a", "WAITING": "#9e9e9e"}
#: points kept per slot's E(t) curve
MAX_POINTS = 4000


class SlotColumn(QWidget):
    """One slot: unit, outcome, current step and E(t)."""

    def __init__(self, slot: int, serial: str) -> None:
        super().__init__()
        self.slot, self.serial = slot, serial
        lay = QVBoxLayout(self)
        self.title = QLabel(f"slot {slot} — {serial}")
        self.title.setAlignment(Qt.AlignmentFlag.AlignCenter)
        self.title.setStyleSheet("font-weight: bold; font-size: 14px")
        self.outcome = QLabel()
        self.outcome.setAlignment(Qt.AlignmentFlag.AlignCenter)
        self.step = QLabel("")
        self.step.setAlignment(Qt.AlignmentFlag.AlignCenter)
        self.step.setWordWrap(True)
        self.plot = pg.PlotWidget()
        self.plot.setLabel("left", "E", units="1")
        self.plot.setLabel("bottom", "time t", units="s")
        self.curve = self.plot.plot(pen=pg.mkPen("#1f77b4", width=1))
        for w in (self.title, self.outcome, self.step, self.plot):
            lay.addWidget(w)
        self.t_s: list[np.ndarray] = []
        self.e: list[np.ndarray] = []
        self.set_outcome("WAITING")

    def set_outcome(self, outcome: str) -> None:
        self.outcome_text = outcome
        self.outcome.setText(outcome)
        self.outcome.setStyleSheet(f"background: {COLOURS.get(outcome, '#9e9e9e')}; color: white; "
                                   "font-size: 18px; font-weight: bold; padding: 4px")

    def add_samples(self, t_s: np.ndarray, e: np.ndarray) -> None:
        self.t_s.append(t_s)
        self.e.append(e)
        t, y = np.concatenate(self.t_s), np.concatenate(self.e)
        if len(t) > MAX_POINTS:  # keep every k-th point: the whole run stays in view
            k = int(np.ceil(len(t) / MAX_POINTS))
            t, y = t[::k], y[::k]
        self.t_s, self.e = [t], [y]
        self.curve.setData(t, y)

    @property
    def points(self) -> int:
        return sum(len(x) for x in self.t_s)


class BatchView(QWidget):
    """A column a slot; `attach(batch)` follows a running bench.engine.batch.Batch."""

    #: stream rows kept per block for E(t) (every k-th): the curve, not the data, is drawn here
    DECIMATE = 50

    def __init__(self, serials: dict[int, str]) -> None:
        super().__init__()
        self.setWindowTitle("gyrobench — batch")
        lay = QHBoxLayout(self)
        self.columns = {n: SlotColumn(n, s) for n, s in sorted(serials.items())}
        for col in self.columns.values():
            lay.addWidget(col)
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._unsubscribe: list[Any] = []
        self.timer = QTimer(self)
        self.timer.timeout.connect(self.drain)
        self.timer.start(100)

    def attach(self, batch: Any) -> None:
        """Follow every slot's runner of `batch` (call before `batch.run`)."""
        for n, runner in batch.runners.items():
            if n in self.columns:
                self._unsubscribe.append(runner.bus.subscribe(lambda e, n=n: self._on_event(n, e)))

    def detach(self) -> None:
        for u in self._unsubscribe:
            u()
        self._unsubscribe.clear()

    def _on_event(self, slot: int, event: Any) -> None:
        """On the slot's thread: keep only what the view draws."""
        if isinstance(event, ev.SampleBlock):
            if event.stream != "fpga" or not len(event.data):
                return
            cols = event.columns
            try:
                idx = [cols.index(c) for c in ("t_s", "cx", "sx", "cy", "sy")]
            except ValueError:
                return
            rows = event.data[:: self.DECIMATE, idx]
            self._queue.put((slot, "E", rows))
        elif isinstance(event, ev.RunStarted):
            self._queue.put((slot, "outcome", "RUNNING"))
        elif isinstance(event, ev.StepStarted):
            self._queue.put((slot, "step", f"step {event.index + 1}/{event.total}: {event.title or event.name}"))
        elif isinstance(event, ev.RunFinished):
            self._queue.put((slot, "outcome", event.outcome))
            self._queue.put((slot, "step", event.end_reason))

    def drain(self) -> None:
        """On the GUI thread: draw what the slots queued."""
        blocks: dict[int, list[np.ndarray]] = {}
        while True:
            try:
                slot, kind, value = self._queue.get_nowait()
            except queue.Empty:
                break
            col = self.columns[slot]
            if kind == "E":
                blocks.setdefault(slot, []).append(value)
            elif kind == "outcome":
                col.set_outcome(value)
            else:
                col.step.setText(value)
        for slot, parts in blocks.items():
            rows = np.vstack(parts)
            e = orbit_elements(rows[:, 1:5])["E"]
            self.columns[slot].add_samples(rows[:, 0], np.asarray(e, dtype=float))
