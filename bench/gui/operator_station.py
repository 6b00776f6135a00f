"""The operator station (`gyrobench gui --operator`): log in, pick a sequence, scan a serial; the unit
runs through the line (bench.line: routing, attempts, unit record, certificate, line database row)
in a worker thread; PASS / FAIL / MARGINAL shows large with its reason, then the next serial.  The
line's prompts (fixture, table spin) appear here as Yes / No buttons; the running step and its
progress show live (bench/gui/unit_progress.py).  On a station with slots each scan fills the next
empty slot (Enter on an empty field leaves it empty), Start runs them as one batch, each slot shows
its verdict, and Retest runs one slot alone (bench/gui/operator_slots.py).  The station's
calibration dates and golden-unit lock show at login; a station out of calibration or locked
refuses to run with one message."""

from __future__ import annotations

import threading
from typing import Any

from PySide6.QtCore import QObject, Qt, QTimer, Signal
from PySide6.QtGui import QFont
from PySide6.QtWidgets import (
    QComboBox,
    QHBoxLayout,
    QLabel,
    QLineEdit,
    QProgressBar,
    QPushButton,
    QSizePolicy,
    QVBoxLayout,
    QWidget,
)

from bench.validation import ValidationError

from .line_station import LineSession, default_sequence, sequences
from .operator_slots import SlotPanel
from .operator_view import COLOURS
from .unit_progress import UnitProgress

COLOURS = {**COLOURS, "LOG IN": ("#d8d8d8", "#333"), "CONDITIONAL": COLOURS["MARGINAL"],
           "NOT RUN": ("#c62020", "white"), "REFUSED": ("#6a1b9a", "white")}


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
                 db: str | None = None, seed: int | None = None, lot: str = "",
                 parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.lot = lot
        self.station_arg, self.runs_dir, self.db_arg, self.seed = station, runs_dir, db, seed
        self.session: LineSession | None = None
        self.records: list[dict[str, Any]] = []
        self.units_done: list[tuple[str, str]] = []
        self.batches_done: list[dict[int, str]] = []  # each batch's (or retest's) outcome by slot
        self.slots: dict[int, SlotPanel] = {}
        self.unit_progress = UnitProgress(1)
        self._thread: threading.Thread | None = None
        self._answer: tuple[dict, threading.Event] | None = None
        self._running_prompt = ""
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
        self.calib = QLabel("")
        self.calib.setObjectName("calibration")
        self.calib.setWordWrap(True)
        self.calib.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Preferred)

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
        self.step_label = QLabel("")
        self.step_label.setObjectName("step")
        self.step_label.setFont(font(13))
        self.step_label.setAlignment(Qt.AlignmentFlag.AlignCenter)
        self.bar = QProgressBar()
        self.bar.setRange(0, 1000)
        self.bar.setTextVisible(False)
        self.bar.setValue(0)
        self.slots_widget = QWidget()
        self.slots_row = QHBoxLayout(self.slots_widget)
        self.slots_row.setContentsMargins(0, 0, 0, 0)
        self.start_button = QPushButton("Start")
        self.start_button.setObjectName("start")
        self.start_button.setMinimumHeight(44)
        self.start_button.setFont(font(16, True))
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
        lay.addWidget(self.calib)
        lay.addWidget(self.verdict)
        lay.addWidget(self.unit_label)
        lay.addWidget(self.reason)
        lay.addWidget(self.slots_widget, 3)
        lay.addWidget(self.step_label)
        lay.addWidget(self.bar)
        lay.addSpacing(10)
        lay.addWidget(self.prompt)
        scan_row = QHBoxLayout()
        scan_row.addWidget(self.serial_field, 1)
        scan_row.addWidget(self.start_button)
        lay.addLayout(scan_row)
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
        self.start_button.clicked.connect(lambda: self.start_batch())
        self.timer = QTimer(self)
        self.timer.timeout.connect(self._show_progress)
        self.timer.start(100)
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
                                       db=self.db_arg, seed=self.seed, lot=self.lot)
        except (ValidationError, ValueError, OSError) as exc:
            self.message.setText(str(exc))
            self.login_button.setEnabled(False)
            return
        self._build_slots()
        self._show_calibration()
        listed = self.session.operators()
        self.operator.setEditable(listed is None and self.session.free_text)
        if listed:
            self.operator.addItems(listed)
        self.login_button.setEnabled(bool(listed) or self.session.free_text)
        self.message.setText(self.session.refusal() or "" if self.login_button.isEnabled() else
                             f"station {self.session.station_id!r}: the line database lists no operators and "
                             "the station takes no typed names")
        self.prompt.setText("Log in: " + ("choose your name" if listed else "type your name"))

    def _build_slots(self) -> None:
        """A panel a slot (a station with slots), else the one unit's verdict."""
        for panel in self.slots.values():
            panel.setParent(None)
            panel.deleteLater()
        self.slots.clear()
        n_steps = len(self.session.seq.steps) if self.session else 1
        self.unit_progress = UnitProgress(n_steps)
        for n in range(1, (self.session.n_slots if self.session else 0) + 1):
            panel = SlotPanel(n, n_steps)
            panel.clear_button.clicked.connect(lambda _c=False, n=n: self.clear_slot(n))
            panel.retest_button.clicked.connect(lambda _c=False, n=n: self.retest_slot(n))
            self.slots_row.addWidget(panel)
            self.slots[n] = panel
        many = bool(self.slots)
        self.slots_widget.setVisible(many)
        self.start_button.setVisible(many)
        self.start_button.setEnabled(False)
        for w in (self.verdict, self.unit_label, self.reason, self.step_label, self.bar):
            w.setVisible(not many)
        self.serial_field.setPlaceholderText(
            "scan a serial (Enter alone leaves the slot empty)" if many
            else "scan or type the serial, then Enter")

    def _show_calibration(self) -> None:
        """The station's calibration dates and golden-unit lock; red when it refuses to run."""
        if self.session is None:
            return
        refused = self.session.refusal()
        self.calib.setText(f"station {self.session.station_id}: {self.session.calibration_status()}")
        self.calib.setStyleSheet("color: #c62020; font-weight: bold;" if refused else "color: #2e5e2e;")

    def refused(self) -> bool:
        """Whether the station refuses to run now (shown as one message); re-read at each unit."""
        why = self.session.refusal() if self.session is not None else None
        self._show_calibration()
        if why:
            self.message.setText(why)
        return bool(why)

    def log_in(self) -> bool:
        if self.session is None or self.busy():
            return False
        try:
            name = self.session.log_in(self.operator.currentText())
        except (ValidationError, ValueError) as exc:
            self.message.setText(str(exc))
            return False
        self.message.setText(self.session.refusal() or "")
        self._show_calibration()
        self.who.setText(f"<b>{name}</b> on {self.session.station_id}, sequence {self.session.seq.name}")
        self._set_verdict("READY")
        self._ask_serial()
        return True

    # --- a unit ---------------------------------------------------------------------------------
    def busy(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def _ask_serial(self) -> None:
        if self.slots:
            free = self._next_free()
            self.start_button.setEnabled(any(p.serial for p in self.slots.values()) and not self.busy())
            self.prompt.setText(f"Scan the unit for slot {free}, or Start" if free else "Every slot is set: Start")
        else:
            self.prompt.setText("Next unit: scan its serial" if self.units_done else "Scan the unit's serial")
        self.serial_field.setEnabled(True)
        self.serial_field.clear()
        self.serial_field.setFocus()

    def _serial_entered(self) -> None:
        if self.session is None or self.session.ctx is None or self.busy():
            return
        if self.slots:
            self._place(self.serial_field.text())
            return
        if self.refused():  # the one message, under the verdict
            self._set_verdict("REFUSED")
            self.reason.setText(self.message.text())
            self.message.setText("")
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
        self._running_prompt = f"{serial}: testing - do not touch the fixture"
        self.prompt.setText(self._running_prompt)
        session, operator = self.session, StationOperator(self, serial)
        why = self.retest.text().strip()
        is_rework = self.retest_kind.currentText() == "rework code"
        rework, reason = (why or None, None) if is_rework else (None, why or None)
        self.retest.clear()
        self.unit_progress.reset()
        self.step_label.setText("")
        self.bar.setValue(0)
        session.ctx.on_runner = lambda runner: self.unit_progress.follow(runner.bus)  # worker thread

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
        self.prompt.setText(self._running_prompt)
        box["value"] = value
        done.set()

    def waiting(self) -> bool:
        """Whether the line waits for a Yes / No."""
        return self._answer is not None

    def _attempt_outcome(self, serial: str, outcome: str, summary: str) -> None:
        if self.slots:
            panel = next((p for p in self.slots.values() if p.serial == serial), None)
            if panel is not None:
                panel.set_verdict(outcome, summary)
            return
        self._set_verdict(outcome)
        self.unit_label.setText(serial)
        self.reason.setText(summary)

    def _unit_finished(self, payload: Any) -> None:
        serial, result = payload
        self.unit_progress.detach()
        self._show_progress()
        if isinstance(serial, dict):
            self._batch_finished(serial, result)
            return
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

    # --- slots -----------------------------------------------------------------------------------
    def _next_free(self) -> int | None:
        """The lowest slot with no unit and not left empty on purpose."""
        return next((n for n, p in self.slots.items() if p.serial is None and p.outcome != "NOT FITTED"), None)

    def _place(self, text: str) -> None:
        """A scan into the next empty slot; an empty scan (Enter alone) leaves that slot empty."""
        if any(p.tested for p in self.slots.values()):  # the last batch's verdicts make way for the next
            for p in self.slots.values():
                p.empty()
        free = self._next_free()
        if free is None:
            self.message.setText("every slot is set: Start, or Clear a slot")
            return
        if not text.strip():
            self.slots[free].empty()
            self.slots[free].set_verdict("NOT FITTED", "left empty: not run")
            self.slots[free].clear_button.setEnabled(True)
            self.message.setText("")
            self._ask_serial()
            return
        try:
            serial = self.session.check_serial(text)
        except (ValidationError, ValueError) as exc:
            self.message.setText(str(exc))
            self.serial_field.selectAll()
            return
        taken = next((n for n, p in self.slots.items() if p.serial == serial), None)
        if taken is not None:
            self.message.setText(f"{serial} is already in slot {taken}")
            self.serial_field.selectAll()
            return
        self.message.setText("")
        self.slots[free].place(serial)
        self.serial_field.clear()
        self._ask_serial()

    def clear_slot(self, n: int) -> None:
        if not self.busy():
            self.slots[n].empty()
            self._ask_serial()

    def start_batch(self, only: int | None = None) -> bool:
        """Run the placed units as one batch (or slot `only` alone: a retest); False when nothing starts."""
        if self.session is None or self.session.ctx is None or self.busy() or not self.slots:
            return False
        if self.refused():
            for p in self.slots.values():
                if p.serial and (only is None or p.slot == only):
                    p.set_verdict("REFUSED", self.message.text())
            return False
        serials = {n: p.serial for n, p in self.slots.items() if p.serial and (only is None or n == only)}
        not_fitted = [n for n, p in self.slots.items() if not p.serial]
        if not serials:
            self.message.setText("no unit placed: scan a serial into a slot first")
            return False
        self.message.setText("")
        why = self.retest.text().strip()
        is_rework = self.retest_kind.currentText() == "rework code"
        rework, reason = (why or None, None) if is_rework else (None, why or None)
        self.retest.clear()
        for n, p in self.slots.items():
            if n in serials:
                p.set_verdict("RUNNING", "")
                p.reset_progress()
                p.tested = False
            elif only is None:
                p.set_verdict("NOT FITTED", "empty slot: not run")
            p.clear_button.setEnabled(False)
            p.retest_button.setEnabled(False)
        for w in (self.serial_field, self.start_button, self.login_button, self.sequence):
            w.setEnabled(False)
        placed = ", ".join(f"{s} (slot {n})" for n, s in serials.items())
        self._running_prompt = ("retest of " if only else "") + f"{placed}: testing - do not touch the fixtures"
        self.prompt.setText(self._running_prompt)
        session, operator = self.session, StationOperator(self, "")

        def on_batch(batch: Any) -> None:  # worker thread, before each step's batch runs
            for n, runner in batch.runners.items():
                if n in self.slots:
                    self.slots[n].progress.follow(runner.bus)

        session.ctx.on_batch = on_batch

        def work() -> None:
            try:
                result: Any = session.run_slots(serials, operator, rework=rework, retest_reason=reason,
                                                not_fitted=not_fitted, alone=only is not None)
            except BaseException as exc:  # noqa: BLE001 - said on the screen, never a traceback
                result = exc
            self.relay.finished.emit((serials, result))

        self._thread = threading.Thread(target=work, name="line-batch", daemon=True)
        self._thread.start()
        return True

    def retest_slot(self, n: int) -> bool:
        """Slot n's unit alone, again (the retest field gives its rework code or reason)."""
        return self.start_batch(only=n)

    def _batch_finished(self, serials: dict[int, str], result: Any) -> None:
        self.sequence.setEnabled(True)
        self.login_button.setEnabled(True)
        self.serial_field.setEnabled(True)
        outcomes: dict[int, str] = {}
        files = []
        if isinstance(result, BaseException):
            self.message.setText(str(result) or type(result).__name__)
            for n in serials:
                self.slots[n].set_verdict("NOT RUN", str(result) or type(result).__name__)
                outcomes[n] = "NOT RUN"
        else:
            self.records.extend(result)
            for rec in result:
                n = int(rec.get("slot") or next(k for k, s in serials.items() if s == rec["serial"]))
                retest = " (retest)" if (rec.get("routing") or {}).get("prior_attempts") else ""
                self.slots[n].set_verdict(str(rec["outcome"]), f"attempt {rec['attempt']}{retest}: "
                                          + str(rec.get("summary", "")))
                outcomes[n] = str(rec["outcome"])
                self.units_done.append((rec["serial"], outcomes[n]))
                self.unit_done.emit(rec["serial"], outcomes[n])
                if rec.get("db_error"):
                    files.append(str(rec["db_error"]))
            files += [f"slot {rec.get('slot')}: record {rec['record_file']}" for rec in result
                      if rec.get("record_file")]
        self.files.setText("\n".join(files))
        for p in self.slots.values():
            p.tested = p.serial is not None
            p.clear_button.setEnabled(p.serial is not None)
            p.retest_button.setEnabled(p.serial is not None)
        self.batches_done.append(outcomes)
        self._ask_serial()
        self.prompt.setText("Done: Retest a slot, or scan the next units (the slots empty at the first scan)")

    def _show_progress(self) -> None:
        """The live step and progress (GUI thread, every 100 ms)."""
        for p in self.slots.values():
            p.show_progress()
        if self.unit_progress.drain():
            self.step_label.setText(self.unit_progress.text)
            self.bar.setValue(int(round(1000 * self.unit_progress.fraction)))

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
    win = OperatorStation(station, sequence=sequence or default_sequence(station), runs_dir=runs_dir, seed=seed)
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
