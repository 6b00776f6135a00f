"""The history browser: the results store's runs in a table, filtered by procedure, station, DUT,
outcome and start date; a selected run opens for replay (its own window), its report (rendered
when not yet there) or its raw file's folder.  Queries run on a worker thread, so a large store
never freezes the window; RUNNING and INTERRUPTED runs show as such."""

from __future__ import annotations

import datetime as _dt
import threading
import time
from pathlib import Path
from typing import Any

from PySide6.QtCore import QAbstractTableModel, QDate, QModelIndex, QObject, Qt, QTimer, Signal
from PySide6.QtGui import QBrush, QColor
from PySide6.QtWidgets import (
    QAbstractItemView,
    QComboBox,
    QDateEdit,
    QGridLayout,
    QHBoxLayout,
    QHeaderView,
    QLabel,
    QLineEdit,
    QMainWindow,
    QPushButton,
    QSizePolicy,
    QTableView,
    QVBoxLayout,
    QWidget,
)

from bench.results.query import RunFilter, filter_choices, find_runs

OUTCOMES = ("COMPLETE", "PASS", "MARGINAL", "FAIL", "ERROR", "ABORTED", "RUNNING", "INTERRUPTED")
OUTCOME_BACKGROUNDS = {"COMPLETE": "#d3ecd3", "PASS": "#d3ecd3", "MARGINAL": "#fde9b8", "ABORTED": "#fde9b8",
                       "FAIL": "#f4c7c3", "ERROR": "#f4c7c3", "INTERRUPTED": "#f4c7c3", "RUNNING": "#cfe2f3"}
COLUMNS = (("started_at", "started (UTC)"), ("run_id", "run"), ("procedure", "procedure"),
           ("station_id", "station"), ("duts", "DUTs"), ("outcome", "outcome"), ("simulated_s", "bench s"),
           ("end_reason", "reason"))
ANY = "(any)"
NO_DATE = QDate(2000, 1, 1)  # a date edit at its minimum shows "any"


class RunsModel(QAbstractTableModel):
    """Rows of `find_runs` for a QTableView (model/view: 10,000 rows cost nothing to show)."""

    def __init__(self, parent: QObject | None = None) -> None:
        super().__init__(parent)
        self.rows: list[dict[str, Any]] = []

    def set_rows(self, rows: list[dict[str, Any]]) -> None:
        self.beginResetModel()
        self.rows = rows
        self.endResetModel()

    def rowCount(self, parent: QModelIndex = QModelIndex()) -> int:  # noqa: B008, N802 - Qt's API
        return 0 if parent.isValid() else len(self.rows)

    def columnCount(self, parent: QModelIndex = QModelIndex()) -> int:  # noqa: B008, N802 - Qt's API
        return len(COLUMNS)

    def headerData(self, section: int, orientation: Qt.Orientation, role: int = Qt.ItemDataRole.DisplayRole) -> Any:  # noqa: N802
        if role == Qt.ItemDataRole.DisplayRole and orientation == Qt.Orientation.Horizontal:
            return COLUMNS[section][1]
        return None

    def data(self, index: QModelIndex, role: int = Qt.ItemDataRole.DisplayRole) -> Any:
        if not index.isValid():
            return None
        row = self.rows[index.row()]
        key = COLUMNS[index.column()][0]
        if role == Qt.ItemDataRole.DisplayRole:
            value = row.get(key)
            if value is None:
                return ""
            if key == "started_at":
                return str(value)[:19].replace("T", " ")
            if key == "simulated_s":
                return f"{float(value):.1f}"
            if key == "end_reason":
                return str(value).splitlines()[0][:160] if value else ""
            return str(value)
        if role == Qt.ItemDataRole.BackgroundRole and key == "outcome":
            colour = OUTCOME_BACKGROUNDS.get(str(row.get("outcome")))
            return QBrush(QColor(colour)) if colour else None
        if role == Qt.ItemDataRole.ToolTipRole and key in ("end_reason", "run_id"):
            return str(row.get("end_reason") or "") + (f"\nraw file: {row.get('raw_file')}" if row.get("raw_file")
                                                        else "")
        return None


class _Relay(QObject):
    """Carries a worker thread's answer to the GUI thread (a queued signal)."""

    done = Signal(int, object)


class HistoryBrowser(QMainWindow):
    """A window over the results store at `store_url` (the station's, by default)."""

    def __init__(self, store_url: str | None = None, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        from bench.results import ResultsStore

        self.setWindowTitle("gyrobench - run history")
        self.resize(1200, 640)
        self.store = ResultsStore(store_url, offline_ok=True)
        self.generation = 0  # the newest query's number: older answers are dropped
        self.last_query_s = 0.0
        self.total = 0
        self.error: str | None = self.store.open_error
        self.replays: list[QWidget] = []
        self.dialog: QWidget | None = None
        self._relay = _Relay(self)
        self._relay.done.connect(self._on_answer)
        self._threads: list[threading.Thread] = []

        self.procedure = QComboBox()
        self.station = QComboBox()
        self.outcome = QComboBox()
        for combo in (self.procedure, self.station, self.outcome):
            combo.addItem(ANY)
            combo.setSizeAdjustPolicy(QComboBox.SizeAdjustPolicy.AdjustToContents)
        self.outcome.addItems(list(OUTCOMES))
        self.dut = QLineEdit()
        self.dut.setPlaceholderText("serial (part of)")
        self.since = self._date_edit()
        self.until = self._date_edit()
        self.refresh_button = QPushButton("Refresh")
        self.count = QLabel("")
        self.count.setObjectName("history_count")
        self.count.setWordWrap(True)
        self.count.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Preferred)

        self.model = RunsModel(self)
        self.view = QTableView()
        self.view.setModel(self.model)
        self.view.setSelectionBehavior(QAbstractItemView.SelectionBehavior.SelectRows)
        self.view.setSelectionMode(QAbstractItemView.SelectionMode.SingleSelection)
        self.view.verticalHeader().setVisible(False)
        self.view.setWordWrap(False)
        header = self.view.horizontalHeader()
        header.setStretchLastSection(True)
        for i, width in enumerate((150, 190, 130, 90, 110, 100, 70)):
            header.resizeSection(i, width)
        header.setSectionResizeMode(QHeaderView.ResizeMode.Interactive)
        self.view.doubleClicked.connect(lambda _i: self.open_replay())

        self.replay_button = QPushButton("Replay")
        self.report_button = QPushButton("Open report")
        self.raw_button = QPushButton("Raw file folder")
        self.raw_path = QLineEdit()
        self.raw_path.setReadOnly(True)
        self.raw_path.setPlaceholderText("raw file of the selected run")
        self.replay_button.clicked.connect(self.open_replay)
        self.report_button.clicked.connect(self.open_report)
        self.raw_button.clicked.connect(self.open_raw_folder)

        filters = QGridLayout()
        for col, (label, widget) in enumerate((("procedure", self.procedure), ("station", self.station),
                                               ("DUT", self.dut), ("outcome", self.outcome),
                                               ("from", self.since), ("to", self.until))):
            filters.addWidget(QLabel(label), 0, col)
            filters.addWidget(widget, 1, col)
        filters.addWidget(self.refresh_button, 1, 6)
        actions = QHBoxLayout()
        for b in (self.replay_button, self.report_button, self.raw_button):
            actions.addWidget(b)
        actions.addWidget(self.raw_path, 1)
        central = QWidget()
        lay = QVBoxLayout(central)
        lay.addLayout(filters)
        lay.addWidget(self.count)
        lay.addWidget(self.view, 1)
        lay.addLayout(actions)
        self.setCentralWidget(central)

        self._debounce = QTimer(self)
        self._debounce.setSingleShot(True)
        self._debounce.setInterval(200)
        self._debounce.timeout.connect(self.query)
        for combo in (self.procedure, self.station, self.outcome):
            combo.currentIndexChanged.connect(lambda _i: self._debounce.start())
        self.dut.textChanged.connect(lambda _t: self._debounce.start())
        for d in (self.since, self.until):
            d.dateChanged.connect(lambda _d: self._debounce.start())
        self.refresh_button.clicked.connect(self.query)
        self.view.selectionModel().selectionChanged.connect(lambda *_a: self._on_selection())
        self._on_selection()
        self._load_choices()
        self.query()

    @staticmethod
    def _date_edit() -> QDateEdit:
        d = QDateEdit()
        d.setCalendarPopup(True)
        d.setDisplayFormat("yyyy-MM-dd")
        d.setMinimumDate(NO_DATE)
        d.setSpecialValueText("any")
        d.setDate(NO_DATE)
        return d

    def _load_choices(self) -> None:
        try:
            choices = filter_choices(self.store)
        except Exception as exc:  # noqa: BLE001 - the store may be down: the browser says so, never crashes
            self.error = f"results store {self.store.display_url}: {exc}"
            return
        for combo, key in ((self.procedure, "procedure"), (self.station, "station_id"), (self.outcome, "outcome")):
            have = {combo.itemText(i) for i in range(combo.count())}
            combo.addItems([v for v in choices[key] if v not in have])

    # --- querying ------------------------------------------------------------------------------
    def current_filter(self) -> RunFilter:
        def pick(combo: QComboBox) -> str:
            return "" if combo.currentText() == ANY else combo.currentText()

        def day(edit: QDateEdit) -> _dt.date | None:
            q = edit.date()
            return None if q == NO_DATE else _dt.date(q.year(), q.month(), q.day())

        return RunFilter(procedure=pick(self.procedure), station_id=pick(self.station), dut=self.dut.text().strip(),
                         outcome=pick(self.outcome), since=day(self.since), until=day(self.until))

    def query(self) -> None:
        """Ask the store on a worker thread; the answer lands in `_on_answer` (the newest only)."""
        self.generation += 1
        gen, flt = self.generation, self.current_filter()
        self.count.setText("searching...")

        def work() -> None:
            t0 = time.perf_counter()
            try:
                answer: Any = (*find_runs(self.store, flt), time.perf_counter() - t0)
            except Exception as exc:  # noqa: BLE001 - shown in the window as one line
                answer = exc
            self._relay.done.emit(gen, answer)

        self._threads = [t for t in self._threads if t.is_alive()]
        thread = threading.Thread(target=work, name="history-query", daemon=True)
        self._threads.append(thread)
        thread.start()

    def busy(self) -> bool:
        return any(t.is_alive() for t in self._threads)

    def _on_answer(self, gen: int, answer: Any) -> None:
        if gen != self.generation:
            return
        if isinstance(answer, Exception):
            self.error = f"results store {self.store.display_url}: {answer}".splitlines()[0]
            self.count.setText(self.error)
            self.count.setStyleSheet("color: #c00000; font-weight: bold;")
            return
        rows, total, seconds = answer
        self.error = None
        self.last_query_s = seconds
        self.total = total
        self.model.set_rows(rows)
        shown = f"{len(rows)} of {total}" if total > len(rows) else f"{total}"
        self.count.setText(f"{shown} run(s) in {self.store.display_url} (query {seconds * 1e3:.0f} ms)")
        self.count.setStyleSheet("")
        self._on_selection()

    # --- the selected run ----------------------------------------------------------------------
    def selected(self) -> dict[str, Any] | None:
        rows = self.view.selectionModel().selectedRows()
        return self.model.rows[rows[0].row()] if rows else None

    def select_run(self, run_id: str) -> bool:
        for i, row in enumerate(self.model.rows):
            if row["run_id"] == run_id:
                self.view.selectRow(i)
                return True
        return False

    def _raw_of(self, row: dict[str, Any] | None) -> Path | None:
        raw = (row or {}).get("raw_file")
        return Path(raw) if raw else None

    def _on_selection(self) -> None:
        row = self.selected()
        raw = self._raw_of(row)
        exists = raw is not None and raw.exists()
        self.raw_path.setText("" if row is None else (str(raw) if raw else "no raw file recorded")
                              + ("" if exists or raw is None else "  (missing)"))
        for b in (self.replay_button, self.report_button, self.raw_button):
            b.setEnabled(exists)

    def open_replay(self) -> QWidget | None:
        """The selected run in its own replay window (a corrupt or incomplete file says so there)."""
        from .replay_view import ReplayWindow

        raw = self._raw_of(self.selected())
        if raw is None:
            return None
        win = ReplayWindow(raw)
        win.show()
        self.replays.append(win)
        return win

    def open_report(self) -> None:
        """Render the selected run's report when needed (with its store row) and open it."""
        from PySide6.QtGui import QGuiApplication

        from .open_report import ensure_report, open_in_browser

        row = self.selected()
        raw = self._raw_of(row)
        if raw is None:
            return
        QGuiApplication.setOverrideCursor(Qt.CursorShape.WaitCursor)
        try:
            path = ensure_report(raw, self.store.get_run(row["run_id"]))
        except Exception as exc:  # noqa: BLE001 - one line in the window, never a traceback
            self.count.setText(f"report of {row['run_id']} failed: {str(exc).splitlines()[0] if str(exc) else exc!r}")
            self.count.setStyleSheet("color: #c00000; font-weight: bold;")
            return
        finally:
            QGuiApplication.restoreOverrideCursor()
        self.dialog = open_in_browser(path, self)

    def open_raw_folder(self) -> None:
        from .open_report import open_in_browser

        raw = self._raw_of(self.selected())
        if raw is not None:
            self.dialog = open_in_browser(raw.parent, self, what="raw file's folder", opener="a file manager")
            if self.dialog is not None:
                self.dialog.path.setText(str(raw.resolve()))

    def closeEvent(self, event) -> None:  # noqa: N802 - Qt's name
        for t in self._threads:
            t.join(timeout=5.0)
        self.store.close()
        super().closeEvent(event)
