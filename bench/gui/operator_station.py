"""The operator station (`gyrobench gui --operator`): log in, pick a sequence, scan a serial; the unit
runs through the line (bench.line: routing, attempts, unit record, certificate, line database row)
in a worker thread; PASS / FAIL / MARGINAL shows large with its reason, then the next serial.  The
line's prompts (fixture, table spin) appear here as Yes / No buttons."""

from __future__ import annotations

import threading
from typing import Any

from PySide6.QtCore import QObject, Qt, Signal
from PySide6.QtGui import QFont
from PySide6.QtWidgets import (
    QComboBox,
    QHBoxLayout,
    QLabel,
    QLineEdit,
    QPushButton,
    QSizePolicy,
    QVBoxLayout,
    QWidget,
)

from bench.validation import ValidationError

from .line_station import LineSession, sequences
from .operator_view import COLOURS

COLOURS = {**COLOURS, "LOG IN": ("#d8d8d8", "#333"), "CONDITIONAL": COLOURS["MARGINAL"]}


class _Relay(QObject):
    """Worker thread -> GUI thread."""

    ask = Signal(str, object)  # a confirmation question, (box, done)
    outcome = Signal(str, str, str)  # serial, outcome, summary (each attempt)
    finished = Signal(object)  # the unit's records, or the exception that stopped it


class StationOperator:
    """bench.line.prompts' Operator for a unit run from the window's worker thread."""

    def __init__(self, window: OperatorStation, serial: str) -> None:
        self.window, self.serial = window, serial

    def scan_serial(self) -> str:
        return self.serial

    def confirm(self, question: str) -> bool:
        box: dict[str, bool] = {}
        done = threading.Event()
        self.window.relay.ask.emit(question, (box, done))
        done.wait()
        return bool(box.get("value"))

    def show_outcome(self, serial: str, outcome: str, summary: str) -> None:
        self.window.relay.outcome.emit(serial, outcome, summary)


class OperatorStation(QWidget):
    """Log in, sequence, serial, verdict: the line on one station for one operator."""

    unit_done = Signal(str, str)  # serial, final outcome

    def __init__(self, station: str | None, *, sequence: str | None = None, runs_dir: str | None = None,
                 db: str | None = None, seed: int | None = None, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.station_arg, self.runs_dir, self.db_arg, self.seed = station, runs_dir, db, seed
        self.session: LineSession | None = None
        self.records: list[dict[str, Any]] = []
        self.units_done: list[tuple[str, str]] = []
        self._thread: threading.Thread | None = None
        self._answer: tuple[dict, threading.Event] | None = None
        self.setWindowTitle("gyrobench - operator station")
        self.resize(1000, 720)
        self.relay = _Relay()
        self.relay.ask.connect(self._ask, Qt.ConnectionType.QueuedConnection)
        self.relay.outcome.connect(self._attempt_outcome, Qt.ConnectionType.QueuedConnection)
        self.relay.finished.connect(self._unit_finished, Qt.ConnectionType.QueuedConnection)

        def font(pt: int, bold: bool = False) -> QFont:
            f = QFont()
            f.setPointSize(pt)
            f.setBold(bold)
            return f

        self.operator = QComboBox()
        self.operator.setObjectName("operator_login")
        self.operator.setMinimumWidth(220)
        self.sequence = QComboBox()
        self.sequence.setObjectName("sequence")
        self.sequence.addItems(sequences())
        if sequence:
            if self.sequence.findText(sequence) < 0:
                self.sequence.addItem(sequence)
            self.sequence.setCurrentText(sequence)
        self.login_button = QPushButton("Log in")
        self.who = QLabel("not logged in")
        top = QHBoxLayout()
        for w in (QLabel("Operator"), self.operator, QLabel("Sequence"), self.sequence, self.login_button):
            top.addWidget(w)
        top.addWidget(self.who, 1)

        self.verdict = QLabel("LOG IN")
        self.verdict.setObjectName("verdict")
        self.verdict.setFont(font(64, True))
        self.verdict.setAlignment(Qt.AlignmentFlag.AlignCenter)
        self.verdict.setMinimumHeight(180)
        self.unit_label = QLabel("")
        self.unit_label.setFont(font(20))
        self.unit_label.setAlignment(Qt.AlignmentFlag.AlignCenter)
        self.reason = QLabel("")
        self.reason.setObjectName("reason")
        self.reason.setFont(font(14))
        self.reason.setWordWrap(True)
        self.reason.setAlignment(Qt.AlignmentFlag.AlignCenter)
        self.reason.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Preferred)
        self.reason.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        self.prompt = QLabel("")
        self.prompt.setFont(font(18, True))
        self.prompt.setWordWrap(True)
        self.serial_field = QLineEdit()
        self.serial_field.setObjectName("serial")
        self.serial_field.setFont(font(22))
        self.serial_field.setPlaceholderText("scan or type the serial, then Enter")
        self.retest = QLineEdit()
        self.retest.setObjectName("retest")
        self.retest.setPlaceholderText("a retest only: after a FAIL the rework code (RW-12), after a PASS why")
        self.retest_kind = QComboBox()
        self.retest_kind.addItems(["rework code", "retest reason"])
        self.yes_button = QPushButton("Yes")
        self.no_button = QPushButton("No")
        for b in (self.yes_button, self.no_button):
            b.setMinimumHeight(48)
            b.setFont(font(16, True))
            b.setEnabled(False)
        answers = QHBoxLayout()
        answers.addWidget(self.yes_button)
        answers.addWidget(self.no_button)
        self.message = QLabel("")
        self.message.setObjectName("message")
        self.message.setWordWrap(True)
        self.message.setStyleSheet("color: #c62020;")
        self.message.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Preferred)
        self.files = QLabel("")
        self.files.setWordWrap(True)
        self.files.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        self.files.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Preferred)

        lay = QVBoxLayout(self)
        lay.addLayout(top)
        lay.addWidget(self.verdict)
        lay.addWidget(self.unit_label)
        lay.addWidget(self.reason)
        lay.addSpacing(10)
        lay.addWidget(self.prompt)
        lay.addWidget(self.serial_field)
        retest_row = QHBoxLayout()
        retest_row.addWidget(self.retest_kind)
        retest_row.addWidget(self.retest, 1)
        lay.addLayout(retest_row)
        lay.addLayout(answers)
        lay.addWidget(self.message)
        lay.addWidget(self.files)
        lay.addStretch(1)

        self.login_button.clicked.connect(self.log_in)
        self.sequence.currentTextChanged.connect(lambda _t: self._open_session())
        self.serial_field.returnPressed.connect(self._serial_entered)
        self.yes_button.clicked.connect(lambda: self._answered(True))
        self.no_button.clicked.connect(lambda: self._answered(False))
        self._set_verdict("LOG IN")
        self.serial_field.setEnabled(False)
        self._open_session()

    # --- session and login ----------------------------------------------------------------------
    def _open_session(self) -> None:
        """The chosen sequence on the station (checked before anyone logs in)."""
        if self.busy():
            return
        if self.session is not None:
            self.session.close()
            self.session = None
        self.operator.clear()
        self.who.setText("not logged in")
        self.serial_field.setEnabled(False)
        try:
            self.session = LineSession(self.station_arg, self.sequence.currentText(), runs_dir=self.runs_dir,
                                       db=self.db_arg, seed=self.seed)
        except (ValidationError, ValueError, OSError) as exc:
            self.message.setText(str(exc))
            self.login_button.setEnabled(False)
            return
        listed = self.session.operators()
        self.operator.setEditable(listed is None and self.session.free_text)
        if listed:
            self.operator.addItems(listed)
        self.login_button.setEnabled(bool(listed) or self.session.free_text)
        self.message.setText("" if self.login_button.isEnabled() else
                             f"station {self.session.station_id!r}: the line database lists no operators and "
                             "the station takes no typed names")
        self.prompt.setText("Log in: " + ("choose your name" if listed else "type your name"))

    def log_in(self) -> bool:
        if self.session is None or self.busy():
            return False
        try:
            name = self.session.log_in(self.operator.currentText())
        except (ValidationError, ValueError) as exc:
            self.message.setText(str(exc))
            return False
        self.message.setText("")
        self.who.setText(f"<b>{name}</b> on {self.session.station_id}, sequence {self.session.seq.name}")
        self._set_verdict("READY")
        self._ask_serial()
        return True

    # --- a unit ---------------------------------------------------------------------------------
    def busy(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def _ask_serial(self) -> None:
        self.prompt.setText("Next unit: scan its serial" if self.units_done else "Scan the unit's serial")
        self.serial_field.setEnabled(True)
        self.serial_field.clear()
        self.serial_field.setFocus()

    def _serial_entered(self) -> None:
        if self.session is None or self.session.ctx is None or self.busy():
            return
        try:
            serial = self.session.check_serial(self.serial_field.text())
        except (ValidationError, ValueError) as exc:
            self.message.setText(str(exc))
            self.serial_field.selectAll()
            return
        self.message.setText("")
        self.serial_field.setText(serial)
        self.serial_field.setEnabled(False)
        self.login_button.setEnabled(False)
        self.sequence.setEnabled(False)
        self._set_verdict("RUNNING")
        self.unit_label.setText(serial)
        self.reason.setText("")
        self.files.setText("")
        self.prompt.setText(f"{serial}: testing - do not touch the fixture")
        session, operator = self.session, StationOperator(self, serial)
        why = self.retest.text().strip()
        is_rework = self.retest_kind.currentText() == "rework code"
        rework, reason = (why or None, None) if is_rework else (None, why or None)
        self.retest.clear()

        def work() -> None:
            try:
                result: Any = session.run_serial(serial, operator, rework=rework, retest_reason=reason)
            except BaseException as exc:  # noqa: BLE001 - said on the screen, never a traceback
                result = exc
            self.relay.finished.emit((serial, result))

        self._thread = threading.Thread(target=work, name=f"line-unit-{serial}", daemon=True)
        self._thread.start()

    def _ask(self, question: str, payload: Any) -> None:
        self._answer = payload
        self.prompt.setText(question)
        self.yes_button.setEnabled(True)
        self.no_button.setEnabled(True)
        self.yes_button.setFocus()

    def _answered(self, value: bool) -> None:
        if self._answer is None:
            return
        (box, done), self._answer = self._answer, None
        self.yes_button.setEnabled(False)
        self.no_button.setEnabled(False)
        self.prompt.setText(f"{self.unit_label.text()}: testing - do not touch the fixture")
        box["value"] = value
        done.set()

    def waiting(self) -> bool:
        """Whether the line waits for a Yes / No."""
        return self._answer is not None

    def _attempt_outcome(self, serial: str, outcome: str, summary: str) -> None:
        self._set_verdict(outcome)
        self.unit_label.setText(serial)
        self.reason.setText(summary)

    def _unit_finished(self, payload: Any) -> None:
        serial, result = payload
        self.sequence.setEnabled(True)
        self.login_button.setEnabled(True)
        if isinstance(result, BaseException):
            outcome = "ERROR"
            self._set_verdict("NOT RUN" if isinstance(result, ValidationError) else outcome)
            self.reason.setText(str(result) or type(result).__name__)
        else:
            self.records.extend(result)
            last = result[-1] if result else {"outcome": "ERROR", "summary": "no record"}
            outcome = str(last["outcome"])
            self._set_verdict(outcome)
            self.reason.setText(str(last.get("summary", "")))
            files = [f"record {last['record_file']}"] if last.get("record_file") else []
            files += [f"{kind} {path}" for kind, path in (last.get("documents") or {}).items()]
            if last.get("db_error"):
                files.append(str(last["db_error"]))
            self.files.setText("\n".join(files))
        self.units_done.append((serial, outcome))
        self.unit_done.emit(serial, outcome)
        self._ask_serial()

    def _set_verdict(self, outcome: str) -> None:
        shown = "CONDITIONAL" if outcome == "MARGINAL" else outcome
        bg, fg = COLOURS.get(shown, ("#c62020", "white"))
        self.verdict.setText(shown)
        self.verdict.setStyleSheet(f"background: {bg}; color: {fg}; border-radius: 12px;")

    def closeEvent(self, event) -> None:  # noqa: N802 - Qt's name
        if self._answer is not None:
            self._answered(False)  # a waiting prompt is answered No: the line stops the unit safely
        if self._thread is not None:
            self._thread.join(120)
        if self.session is not None:
            self.session.close()
        super().closeEvent(event)


def run_station(station: str | None, *, sequence: str | None = None, runs_dir: str | None = None, seed: int = 0,
                screenshot: str | None = None, serial: str = "DEMO-0001", operator: str = "demo") -> int:
    """Open the operator station (blocking until it closes); with `screenshot`, log in as `operator`,
    test `serial` headless (answering Yes), save the window as a PNG and exit."""
    import os
    import time

    from .app import QuitOnSignal, _app, has_display

    if screenshot is None and not os.environ.get("QT_QPA_PLATFORM") and not has_display():
        raise SystemExit("gyrobench gui --operator: no display (DISPLAY / WAYLAND_DISPLAY unset); use --screenshot "
                         "FILE to run headless, or set QT_QPA_PLATFORM")
    app = _app()
    win = OperatorStation(station, sequence=sequence or "ci-spin", runs_dir=runs_dir, seed=seed)
    guard = QuitOnSignal().install()
    try:
        win.show()
        if screenshot is None:
            guard.watch(win)
            code = int(app.exec())
            return guard.exit_code or code
        win.operator.setEditText(operator)
        if not win.log_in():
            raise SystemExit(f"gyrobench gui --operator: {win.message.text()}")
        win.serial_field.setText(serial)
        win._serial_entered()
        deadline = time.monotonic() + 600
        while not win.units_done and time.monotonic() < deadline:
            app.processEvents()
            if win.waiting():
                win.yes_button.click()
            time.sleep(0.005)
        app.processEvents()
        win.grab().save(str(screenshot), "PNG")
        print(f"screenshot {screenshot}: unit {win.units_done[-1] if win.units_done else None}")
        return 0
    finally:
        guard.uninstall()
        win.close()
