"""The small panels around the plots: station, steps, log, results."""

from __future__ import annotations

import html
import math
from typing import Any

from PySide6.QtCore import Qt, Signal
from PySide6.QtGui import QBrush, QColor
from PySide6.QtWidgets import (
    QComboBox,
    QHBoxLayout,
    QLabel,
    QProgressBar,
    QPushButton,
    QSizePolicy,
    QSplitter,
    QTableWidget,
    QTableWidgetItem,
    QTabWidget,
    QTreeWidget,
    QTreeWidgetItem,
    QVBoxLayout,
    QWidget,
)

from bench import numbers
from bench.engine.measurement import NOT_MEASURED

from .backend import SPEEDS
from .log_view import LogPane  # noqa: F401 - the window's log (levels in colour, filter, follows)

OUTCOME_COLOURS = {"PASS": "#b7e4b7", "FAIL": "#f4b6b6", "MARGINAL": "#ffe29a", "ERROR": "#f4b6b6",
                   "ABORTED": "#dddddd", "COMPLETE": "#ffffff", "RUNNING": "#cfe3ff", "INTERRUPTED": "#f4b6b6"}
DEVICE_LABELS = {"rate_dps": "table rate [deg/s]", "angle_deg": "table angle [deg]", "drive": "drive output",
                 "frames": "stream frames received", "lost": "stream frames lost",
                 "crc_errors": "frames rejected (CRC/malformed)", "enabled": "table enabled"}
STATUS_MARKS = {"running": "\u25b6", "done": "\u2713", "error": "\u2717", "aborted": "\u25a0", "skipped": "-",
                "pending": " "}


class StationPanel(QWidget):
    """Devices of the station (connected, table rate and angle, drive, link counters) and, on a
    simulated station, the clock speed control."""

    speed_changed = Signal(float)

    def __init__(self, station: str, simulated: bool, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        lay = QVBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        self.title = QLabel(f"<b>{station}</b> ({'simulated' if simulated else 'real'})")
        lay.addWidget(self.title)
        self.tree = QTreeWidget()
        self.tree.setHeaderLabels(["device", "value"])
        self.tree.setRootIsDecorated(True)
        self.tree.setMinimumHeight(120)
        self.tree.setColumnWidth(0, 150)
        lay.addWidget(self.tree)
        row = QHBoxLayout()
        row.addWidget(QLabel("speed"))
        self.speed = QComboBox()
        self.speed.setObjectName("speed")
        for label, value in SPEEDS:
            self.speed.addItem(label, value)
        self.speed.setCurrentIndex(len(SPEEDS) - 1)
        self.speed.setEnabled(simulated)
        self.speed.currentIndexChanged.connect(lambda i: self.speed_changed.emit(float(self.speed.itemData(i))))
        row.addWidget(self.speed)
        self.sim_time = QLabel("t = 0.0 s")
        row.addWidget(self.sim_time)
        lay.addLayout(row)
        self._items: dict[str, QTreeWidgetItem] = {}

    def set_speed(self, speed: float) -> None:
        for i in range(self.speed.count()):
            v = float(self.speed.itemData(i))
            if v == speed or (math.isinf(v) and math.isinf(speed)):
                self.speed.setCurrentIndex(i)

    def set_time(self, t_sim_s: float) -> None:
        self.sim_time.setText(f"t = {t_sim_s:.1f} s")

    def update_devices(self, devices: dict[str, dict[str, Any]]) -> None:
        """Show each device's fields as read; one that does not answer is marked DOWN in red with
        the reason, and a field no longer read disappears (no stale values)."""
        for name, fields in devices.items():
            item = self._items.get(name)
            if item is None:
                item = QTreeWidgetItem([name, ""])
                self.tree.addTopLevelItem(item)
                self._items[name] = item
                item.setExpanded(True)
            connected = fields.get("connected")
            error = fields.get("error")
            if connected is False or error:
                text = f"DOWN: {error}" if error else "DOWN (disconnected)"
            else:
                text = "connected" if connected else ""
            item.setText(1, text)
            item.setToolTip(1, text)
            item.setForeground(1, QBrush(QColor("#207020" if text == "connected" else "#c00000")))
            shown = {k: v for k, v in fields.items() if k not in ("connected", "error")}
            existing = {item.child(i).text(0): item.child(i) for i in range(item.childCount())}
            for key in set(existing) - set(shown):
                item.removeChild(existing.pop(key))
            for key, value in shown.items():
                label = DEVICE_LABELS.get(key, key)
                text = f"{value:.3f}" if isinstance(value, float) else ("on" if value is True else
                                                                     "off" if value is False else str(value))
                child = existing.get(key)
                if child is None:
                    child = QTreeWidgetItem([key, text])
                    item.addChild(child)
                child.setText(1, text)
                child.setToolTip(0, label)

    def value(self, device: str, key: str) -> str | None:
        """The text shown for one field of one device (None when absent)."""
        item = self._items.get(device)
        if item is None:
            return None
        for i in range(item.childCount()):
            if item.child(i).text(0) == key:
                return item.child(i).text(1)
        return None

    def state(self, device: str) -> str | None:
        item = self._items.get(device)
        return None if item is None else item.text(1)


class StepList(QWidget):
    """The run's steps with a mark for each and a progress bar for the current one."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        lay = QVBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        self.tree = QTreeWidget()
        self.tree.setHeaderLabels(["", "step"])
        self.tree.setRootIsDecorated(False)
        self.tree.setColumnWidth(0, 24)
        lay.addWidget(self.tree)
        self.progress = QProgressBar()
        self.progress.setRange(0, 1000)
        self.message = QLabel("")
        lay.addWidget(self.progress)
        lay.addWidget(self.message)
        self.status: dict[str, str] = {}

    def set_steps(self, steps: tuple[str, ...]) -> None:
        self.tree.clear()
        self.status = {}
        for s in steps:
            self.tree.addTopLevelItem(QTreeWidgetItem([STATUS_MARKS["pending"], s]))
            self.status[s] = "pending"
        self.progress.setValue(0)
        self.message.setText("")

    def _item(self, name: str) -> QTreeWidgetItem:
        for i in range(self.tree.topLevelItemCount()):
            it = self.tree.topLevelItem(i)
            if it.text(1) == name:
                return it
        it = QTreeWidgetItem([STATUS_MARKS["pending"], name])
        self.tree.addTopLevelItem(it)
        return it

    def set_status(self, name: str, status: str) -> None:
        self.status[name] = status
        self._item(name).setText(0, STATUS_MARKS.get(status, "?"))
        if status == "running":  # a new step: its own progress, not the last step's words
            self.progress.setValue(0)
            self.message.setText("")
        elif status == "done":  # a finished step is whole (one that reported no progress read 0 %)
            self.progress.setValue(self.progress.maximum())

    def set_progress(self, fraction: float, message: str) -> None:
        self.progress.setValue(int(round(1000 * min(1.0, max(0.0, fraction)))))
        self.message.setText(message)


class ResultsTable(QWidget):
    """Measurements with value, 95 % interval, limits, a PASS/FAIL/MARGINAL colour and, on a
    simulated station, the truth; a declared measurement never reported reads "not measured".
    The table is as tall as its rows; a button opens the run's report when there is one."""

    HEADERS = ("measurement", "value", "95% interval", "unit", "limits", "outcome", "truth")

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        lay = QVBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        self.table = QTableWidget(0, len(self.HEADERS))
        self.table.setHorizontalHeaderLabels(self.HEADERS)
        self.table.verticalHeader().setVisible(False)
        self.table.horizontalHeader().setStretchLastSection(True)
        self.table.setVerticalScrollBarPolicy(Qt.ScrollBarPolicy.ScrollBarAsNeeded)
        lay.addWidget(self.table, 1)  # the room goes to the rows first, up to their height
        self.truths: dict[str, float] = {}
        self.periods: dict[str, float] = {}
        self.no_truth: dict[str, str] = {}
        self._split_before: list[int] | None = None  # the plots/results split before the rows grew it
        row = QHBoxLayout()
        self.outcome = QLabel("")
        self.outcome.setWordWrap(True)  # a long reason wraps; it never pushes "Open report" away
        self.outcome.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Preferred)
        self.outcome.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        row.addWidget(self.outcome, 1)
        self.report_button = QPushButton("Open report")
        self.report_button.setEnabled(False)
        row.addWidget(self.report_button)
        lay.addLayout(row)
        lay.addStretch(0)  # what the rows do not need stays below the report button
        self.report_path: str | None = None
        self._fit_rows()

    def clear(self) -> None:
        self.table.setRowCount(0)
        self.outcome.setText("")
        self.report_path = None
        self.report_button.setEnabled(False)
        self.truths = {}
        self.periods = {}
        self.no_truth = {}
        self._fit_rows()

    def set_truth(self, truths: dict[str, float], periods: dict[str, float] | None = None,
                  no_truth: dict[str, str] | None = None) -> None:
        """The simulator's true value of each measurement, by name (empty on a real bench), the
        period of each periodic one (an axis angle), compared at its nearest image as in the report,
        and why a measurement is compared with no truth (shown in its truth cell when truths are)."""
        self.truths = dict(truths)
        self.periods = dict(periods or {})
        self.no_truth = dict(no_truth or {}) if self.truths else {}

    def add(self, name: str, value: float, unit: str, low: float | None, high: float | None, outcome: str,
            dut: str | None = None, ci95: tuple[float, float] | None = None, truth: float | None = None) -> None:
        r = self.table.rowCount()
        self.table.insertRow(r)
        label = name if dut is None else f"{name} [{dut}]"
        truth = self.truths.get(name) if truth is None else truth
        measured = outcome != NOT_MEASURED and value is not None and math.isfinite(value)
        value_text, interval_text = _value_and_interval(value, ci95) if measured else ("not measured", "")
        cells = (label, value_text, interval_text, numbers.pretty_unit(unit), _limits(low, high),
                 outcome.replace("_", " ") if outcome == NOT_MEASURED else outcome,
                 _truth(truth, ci95 if measured else None, value if measured else None, self.periods.get(name)))
        colour = QColor(OUTCOME_COLOURS.get(outcome, "#ffffff"))
        for c, text in enumerate(cells):
            item = QTableWidgetItem(text)
            item.setFlags(item.flags() & ~Qt.ItemFlag.ItemIsEditable)
            item.setBackground(QBrush(colour))
            if not measured and c in (1, 5):
                item.setForeground(QBrush(QColor("#707070")))
            if c == 6 and truth is None and name in self.no_truth:  # compared with no truth: why, as the report
                item.setText("not compared")
                item.setToolTip(self.no_truth[name])
                item.setForeground(QBrush(QColor("#707070")))
            self.table.setItem(r, c, item)
        self._fit_rows()

    def _fit_rows(self) -> None:
        """Columns to their contents, and the table as tall as its rows (at least one) where there is room."""
        self.table.resizeColumnsToContents()
        self.table.resizeRowsToContents()
        rows = sum(self.table.rowHeight(r) for r in range(self.table.rowCount()))
        rows = max(rows, self.table.verticalHeader().defaultSectionSize())
        bar = self.table.horizontalScrollBar().sizeHint().height()
        head = self.table.horizontalHeader().sizeHint().height() + bar + 2 * self.table.frameWidth()
        # as tall as its rows where there is room; never taller, and never making the window taller
        self.table.setMaximumHeight(head + rows)
        self.table.setMinimumHeight(head + min(rows, 2 * self.table.verticalHeader().defaultSectionSize()))
        self._grow_pane(head + rows)

    def _grow_pane(self, table_h: int) -> None:
        """In the window's plots/results splitter, give the results pane the height its rows need
        (at most half the splitter; it only grows, so the operator's own split stands otherwise)."""
        child, parent = self, self.parentWidget()
        vertical = Qt.Orientation.Vertical
        while parent is not None and not (isinstance(parent, QSplitter) and parent.orientation() == vertical):
            child, parent = parent, parent.parentWidget()
        if parent is None or parent.count() != 2 or parent.widget(1) is not child:
            return
        sizes = parent.sizes()
        extra = child.height() - self.table.height()  # tab bar, outcome line, report button
        want = min(sum(sizes) // 2, table_h + extra + self.outcome.sizeHint().height())
        if table_h <= 0 or self.table.rowCount() == 0:  # cleared: the split from before the rows came back
            if self._split_before is not None:
                parent.setSizes(self._split_before)
                self._split_before = None
            return
        if want > sizes[1]:
            if self._split_before is None:
                self._split_before = sizes
            parent.setSizes([sum(sizes) - want, want])

    def set_outcome(self, outcome: str, safe_state: bool, reason: str) -> None:
        """The run's outcome and reason in its colour; when the run did not complete, measurements
        it listed as COMPLETE say so (they are not a completed run's results)."""
        safe = "safe state confirmed" if safe_state else "SAFE STATE NOT CONFIRMED"
        colour = OUTCOME_COLOURS.get(outcome, "#ffffff")
        self.outcome.setText(f"<b>{outcome}</b> - {html.escape(reason)} - {safe}")
        self.outcome.setStyleSheet(f"background: {colour}; padding: 2px;")
        if outcome in ("COMPLETE", "PASS", "FAIL", "MARGINAL"):
            return
        col = self.HEADERS.index("outcome")
        for r in range(self.table.rowCount()):
            item = self.table.item(r, col)
            if item is not None and item.text() == "COMPLETE":
                item.setText(f"not confirmed (run {outcome})")
                for c in range(self.table.columnCount()):
                    cell = self.table.item(r, c)
                    if cell is not None:
                        cell.setBackground(QBrush(QColor(colour)))

    def set_report(self, path: str | None) -> None:
        self.report_path = path
        self.report_button.setEnabled(path is not None)


def _value_and_interval(value: float, ci95: tuple[float, float] | None) -> tuple[str, str]:
    """The report's digit rule (bench.numbers.with_interval): two significant digits of the
    interval's half-width; four significant digits and no interval text without one."""
    text, interval = numbers.with_interval(value, ci95)
    return text, "" if interval == numbers.DASH else interval


def _limits(low: float | None, high: float | None) -> str:
    """Limits as the report writes them ('[lo, hi]', '≥ lo', '≤ hi'), '' without any."""
    text = numbers.limits(low, high)
    return "" if text == numbers.DASH else text


def _truth(truth: float | None, ci95: tuple[float, float] | None, value: float | None = None,
           period: float | None = None) -> str:
    """The simulated truth at the value's precision, marked when the 95 % interval holds it (or
    misses it; an axis angle's nearest image, as the report compares)."""
    if truth is None:
        return ""
    text = numbers.truth_text(truth, ci95)
    shown = value if value is not None else truth
    outside = None if ci95 is None else numbers.truth_outside(shown, truth, ci95, period)
    if outside is None:
        return text
    return f"{text} ({'OUTSIDE' if outside else 'in'} the interval)"


def plots_over_tabs(plots: QWidget, results: QWidget, log: QWidget) -> tuple[QSplitter, QTabWidget]:
    """The plots above a Results | Log tab pair (3:1), as the live and the replay windows lay them out."""
    tabs = QTabWidget()
    tabs.addTab(results, "Results")
    tabs.addTab(log, "Log")
    right = QSplitter(Qt.Orientation.Vertical)
    right.addWidget(plots)
    right.addWidget(tabs)
    right.setStretchFactor(0, 3)
    right.setStretchFactor(1, 1)
    return right, tabs
