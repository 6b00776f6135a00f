"""`gyrobench line run SEQUENCE --station sim-hrg-4 --dut ... --window`: the batch's columns
(BatchView: a slot's unit, outcome, current step and live E(t)) in a window on the main thread,
while the line runs the batch in a worker thread.  Abort, closing the window or Ctrl-C aborts every
slot (each slot's drive cut, then the table to rest); the window stays, with the units' outcomes,
until it is closed (or at once with --close-when-done)."""

from __future__ import annotations

import signal
import threading
from collections.abc import Callable
from typing import Any

from PySide6.QtCore import QTimer
from PySide6.QtGui import QCloseEvent
from PySide6.QtWidgets import QApplication, QHBoxLayout, QLabel, QPushButton, QVBoxLayout, QWidget

from .batch_view import BatchView


class BatchWindow(QWidget):
    """BatchView with a status line and an Abort button; closing it while the batch runs aborts."""

    def __init__(self, serials: dict[int, str], abort: Callable[[str], None], running: Callable[[], bool]) -> None:
        super().__init__()
        self.setWindowTitle(f"gyrobench — batch of {len(serials)}")
        self._abort, self._running = abort, running
        self.view = BatchView(serials)
        self.status = QLabel("running")
        self.abort_button = QPushButton("Abort")
        self.abort_button.clicked.connect(lambda: self._abort("operator abort from the window"))
        bar = QHBoxLayout()
        bar.addWidget(self.status, 1)
        bar.addWidget(self.abort_button)
        lay = QVBoxLayout(self)
        lay.addWidget(self.view, 1)
        lay.addLayout(bar)

    def closeEvent(self, event: QCloseEvent) -> None:  # noqa: N802 - Qt's name
        if self._running():
            self._abort("the window was closed")
        event.accept()


def run_batch_in_window(serials: dict[int, str], work: Callable[[], list[dict[str, Any]]], ctx: Any, *,
                        close_when_done: bool = False) -> list[dict[str, Any]]:
    """Run `work` (the batch attempt) in a worker thread with the window on this thread; its records."""
    app = QApplication.instance() or QApplication([])
    app.setQuitOnLastWindowClosed(False)
    batches: list[Any] = []
    done = threading.Event()
    result: dict[str, Any] = {}

    def abort(reason: str) -> None:  # each run ends "aborted: <reason>", as after a signal
        if not ctx.aborted:
            ctx.aborted.append(f"aborted: {reason}")
        for b in list(batches):
            b.abort(reason)
        win.status.setText(f"aborted: {reason}: bringing every slot to its safe state")

    win = BatchWindow(serials, abort, lambda: not done.is_set())

    def on_batch(batch: Any) -> None:  # on the worker thread, before the batch runs
        batches.append(batch)
        win.view.attach(batch)

    ctx.on_batch = on_batch

    def run() -> None:
        try:
            result["records"] = work()
        except BaseException as exc:  # noqa: BLE001 - handed to the caller on its own thread
            result["error"] = exc
        finally:
            done.set()

    def tick() -> None:  # also lets Python run its signal handlers while Qt waits
        if done.is_set() and "shown" not in result:
            result["shown"] = True
            win.view.drain()
            recs = result.get("records") or []
            counts: dict[str, int] = {}
            for r in recs:
                counts[r["outcome"]] = counts.get(r["outcome"], 0) + 1
                col = next((c for c in win.view.columns.values() if c.serial == r["serial"]), None)
                if col is not None:
                    col.set_outcome(r["outcome"])
            win.status.setText("batch done: " + ", ".join(f"{k} {v}" for k, v in sorted(counts.items()))
                               + ("" if close_when_done else " — close the window to finish"))
            win.abort_button.setEnabled(False)
            if close_when_done:
                win.close()
        if done.is_set() and not win.isVisible():
            app.quit()

    previous = signal.signal(signal.SIGINT, lambda *_: abort("SIGINT"))
    timer = QTimer()
    timer.timeout.connect(tick)
    timer.start(100)
    worker = threading.Thread(target=run, name="line-batch", daemon=True)
    win.resize(1400, 480)
    win.show()
    worker.start()
    try:
        app.exec()
    finally:
        timer.stop()
        signal.signal(signal.SIGINT, previous)
        worker.join()
        win.view.detach()
    if "error" in result:
        raise result["error"]
    return result["records"]
