"""The line operator's window (`gyrobench gui --operator`): one big PASS/FAIL/MARGINAL display,
the serial scan field, the fixture and table-spin confirmations, and the next unit's prompt.

One unit is a short list of procedures (the steps) run one after the other on the station with
the scanned serial as the DUT; a step that FAILs, errs or is aborted stops the unit.  The unit's
outcome is the worst of its steps'.  `operator()` gives the same prompts to a line sequence
running in another thread (the bench.line.prompts Operator interface)."""

from __future__ import annotations

import threading
from typing import Any

from PySide6.QtCore import QObject, Qt, QTimer, Signal
from PySide6.QtGui import QFont
from PySide6.QtWidgets import QHBoxLayout, QLabel, QLineEdit, QPushButton, QVBoxLayout, QWidget

from bench.engine import events as ev
from bench.line.prompts import OperatorError, check_serial

from .bridge import EventBridge

RANK = {"PASS": 0, "COMPLETE": 0, "MARGINAL": 1, "FAIL": 2, "ERROR": 3, "ABORTED": 3, "INTERRUPTED": 3}
STOPS = ("FAIL", "ERROR", "ABORTED", "INTERRUPTED")
COLOURS = {"PASS": ("#1e8c1e", "white"), "COMPLETE": ("#1e8c1e", "white"), "MARGINAL": ("#e0a800", "black"),
           "FAIL": ("#c62020", "white"), "ERROR": ("#c62020", "white"), "ABORTED": ("#c62020", "white"),
           "RUNNING": ("#3b6fb6", "white"), "READY": ("#d8d8d8", "#333")}  # fmt: skip


def worst(outcomes: list[str]) -> str:
    """The worst outcome of a unit's steps (none: ERROR)."""
    return max(outcomes, key=lambda o: RANK.get(o, 3)) if outcomes else "ERROR"


class OperatorView(QWidget):
    """The operator's screen on a GuiBackend (EngineBackend): scan, confirm, run, verdict, next."""

    unit_finished = Signal(str, str)  # serial, outcome

    def __init__(self, backend: Any, steps: list[tuple[str, dict[str, Any]]], *, operator_name: str = "",
                 parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.backend = backend
        self.steps = list(steps)
        self.operator_name = operator_name
        self.needs_spin = any("table" in _requires(name) for name, _ in self.steps)
        self.serial = ""
        self.outcomes: list[str] = []
        self.summary_parts: list[str] = []
        self.units_done: list[tuple[str, str]] = []
        self._step = -1
        self.setWindowTitle(f"gyrobench — line operator ({getattr(backend, 'station_name', '')})")
        self.resize(900, 640)

        big = QFont()
        big.setPointSize(64)
        big.setBold(True)
        self.verdict = QLabel("READY")
        self.verdict.setFont(big)
        self.verdict.setAlignment(Qt.AlignmentFlag.AlignCenter)
        self.verdict.setMinimumHeight(200)
        self.unit_label = QLabel("")
        self.unit_label.setAlignment(Qt.AlignmentFlag.AlignCenter)
        mid = QFont()
        mid.setPointSize(20)
        self.unit_label.setFont(mid)
        self.summary = QLabel("")
        self.summary.setAlignment(Qt.AlignmentFlag.AlignCenter)
        self.summary.setWordWrap(True)
        small = QFont()
        small.setPointSize(13)
        self.summary.setFont(small)

        prompt_font = QFont()
        prompt_font.setPointSize(18)
        prompt_font.setBold(True)
        self.prompt = QLabel("")
        self.prompt.setFont(prompt_font)
        self.serial_field = QLineEdit()
        self.serial_field.setPlaceholderText("scan or type the serial, then Enter")
        field_font = QFont()
        field_font.setPointSize(22)
        self.serial_field.setFont(field_font)
        self.serial_field.returnPressed.connect(self._serial_entered)
        self.message = QLabel("")
        self.message.setStyleSheet("color: #c62020;")
        self.fixture_button = QPushButton("Unit is in the fixture, clamped and connected")
        self.spin_button = QPushButton("Table area clear — the table may spin")
        for b in (self.fixture_button, self.spin_button):
            b.setMinimumHeight(48)
            b.setFont(mid)
        self.fixture_button.clicked.connect(self._fixture_confirmed)
        self.spin_button.clicked.connect(self._spin_confirmed)
        self.status = QLabel("")

        layout = QVBoxLayout(self)
        layout.addWidget(self.verdict)
        layout.addWidget(self.unit_label)
        layout.addWidget(self.summary)
        layout.addSpacing(12)
        layout.addWidget(self.prompt)
        row = QHBoxLayout()
        row.addWidget(self.serial_field)
        layout.addLayout(row)
        layout.addWidget(self.message)
        layout.addWidget(self.fixture_button)
        layout.addWidget(self.spin_button)
        layout.addWidget(self.status)
        layout.addStretch(1)

        self.bridge = EventBridge(backend.bus, self)
        self.bridge.events.connect(self._on_events)
        self._poll = QTimer(self)  # starts the next step once the last one's thread has ended
        self._poll.setInterval(30)
        self._poll.timeout.connect(self._maybe_next)
        self._pending_next = False
        self._serial_waiter: Any = None  # a GuiOperator waiting for the scan (else the window's own flow)
        self._confirm_waiter: Any = None  # a GuiOperator waiting for a confirmation
        self._set_verdict("READY")
        self._ask_serial()

    # --- the display --------------------------------------------------------------------------
    def _set_verdict(self, outcome: str) -> None:
        bg, fg = COLOURS.get(outcome, ("#c62020", "white"))
        self.verdict.setText(outcome)
        self.verdict.setStyleSheet(f"background: {bg}; color: {fg}; border-radius: 12px;")

    def show_outcome(self, serial: str, outcome: str, summary: str) -> None:
        """The big verdict for a unit (also the Operator interface's)."""
        self._set_verdict(outcome)
        self.unit_label.setText(serial)
        self.summary.setText(summary)

    # --- the flow -----------------------------------------------------------------------------
    def _ask_serial(self) -> None:
        self.prompt.setText("Next unit: scan its serial" if self.units_done else "Scan the unit's serial")
        self.serial_field.setEnabled(True)
        self.serial_field.clear()
        self.serial_field.setFocus()
        self.fixture_button.setEnabled(False)
        self.spin_button.setEnabled(False)

    def _serial_entered(self) -> None:
        try:
            self.serial = check_serial(self.serial_field.text())
        except OperatorError as exc:
            self.message.setText(str(exc))
            self.serial_field.selectAll()
            return
        self.message.setText("")
        self.serial_field.setText(self.serial)
        self.serial_field.setEnabled(False)
        if self._serial_waiter is not None:
            waiter, self._serial_waiter = self._serial_waiter, None
            waiter(self.serial)
            return
        self.prompt.setText(f"{self.serial}: confirm the unit is in the fixture")
        self.fixture_button.setEnabled(True)
        self.fixture_button.setFocus()

    def _fixture_confirmed(self) -> None:
        self.fixture_button.setEnabled(False)
        if self._confirm_waiter is not None:
            waiter, self._confirm_waiter = self._confirm_waiter, None
            waiter(True)
            return
        if self.needs_spin:
            self.prompt.setText(f"{self.serial}: confirm before the table spins")
            self.spin_button.setEnabled(True)
            self.spin_button.setFocus()
        else:
            self._start_unit()

    def _spin_confirmed(self) -> None:
        self.spin_button.setEnabled(False)
        self._start_unit()

    def _start_unit(self) -> None:
        self.outcomes, self.summary_parts, self._step = [], [], -1
        self.show_outcome(self.serial, "RUNNING", "")
        self.prompt.setText(f"{self.serial}: testing — do not touch the fixture")
        runner = getattr(self.backend, "runner", None)
        if runner is not None:
            runner.duts = [self.serial]
            if self.operator_name:
                runner.operator = self.operator_name
        self._next_step()

    def _next_step(self) -> None:
        self._step += 1
        if self._step >= len(self.steps) or (self.outcomes and self.outcomes[-1] in STOPS):
            self._finish_unit()
            return
        name, values = self.steps[self._step]
        self.status.setText(f"step {self._step + 1}/{len(self.steps)}: {name}")
        try:
            self.backend.start(name, dict(values))
        except Exception as exc:  # noqa: BLE001 - a step that cannot start is the unit's ERROR, said once
            self.outcomes.append("ERROR")
            self.summary_parts.append(f"{name}: did not start ({exc})")
            self._finish_unit()

    def _on_events(self, events: list) -> None:
        for e in events:
            if isinstance(e, ev.Progress) and e.message:
                self.status.setText(f"step {self._step + 1}/{len(self.steps)}: {e.message}")
            elif isinstance(e, ev.RunFinished) and self._step >= 0:
                self.outcomes.append(e.outcome)
                name = self.steps[self._step][0]
                unsafe = "" if e.safe_state else " (safe state NOT confirmed)"
                self.summary_parts.append(f"{name} {e.outcome}{unsafe}")
                self._pending_next = True
                self._poll.start()

    def _maybe_next(self) -> None:
        if self._pending_next and not self.backend.running():
            self._pending_next = False
            self._poll.stop()
            self._next_step()

    def _finish_unit(self) -> None:
        outcome = worst(self.outcomes)
        self.units_done.append((self.serial, outcome))
        self.show_outcome(self.serial, outcome, "; ".join(self.summary_parts))
        self.status.setText(f"{len(self.units_done)} unit(s) this session")
        self._step = -1
        self.unit_finished.emit(self.serial, outcome)
        self._ask_serial()

    # --- the Operator interface for a sequence in another thread ------------------------------
    def waiting(self) -> str | None:
        """What a sequence in another thread waits for: "serial", "confirm" or None."""
        if self._serial_waiter is not None:
            return "serial"
        return "confirm" if self._confirm_waiter is not None else None

    def operator(self) -> GuiOperator:
        return GuiOperator(self)


class _Asker(QObject):
    ask = Signal(str, object)


class GuiOperator:
    """bench.line.prompts' Operator on the window, for a sequence running in a worker thread:
    each call shows its prompt in the GUI thread and waits for the operator's answer."""

    def __init__(self, view: OperatorView) -> None:
        self.view = view
        self._asker = _Asker()
        self._asker.ask.connect(self._in_gui, Qt.ConnectionType.QueuedConnection)

    def _call(self, kind: str, *args: Any) -> Any:
        done = threading.Event()
        box: dict[str, Any] = {}
        self._asker.ask.emit(kind, (args, box, done))
        done.wait()
        return box.get("value")

    def _in_gui(self, kind: str, payload: Any) -> None:
        args, box, done = payload
        view = self.view
        if kind == "outcome":
            view.show_outcome(*args)
            done.set()
            return
        def answer(value: Any) -> None:
            box["value"] = value
            done.set()

        if kind == "serial":
            view.prompt.setText("Scan the unit's serial")
            view._serial_waiter = answer
            view.serial_field.setEnabled(True)
            view.serial_field.clear()
            view.serial_field.setFocus()
            return
        # a confirmation: the fixture button, relabelled with the question while it is asked
        label = view.fixture_button.text()

        def confirmed(value: Any) -> None:
            view.fixture_button.setText(label)
            answer(value)

        view.prompt.setText(args[0])
        view.fixture_button.setText(args[0])
        view._confirm_waiter = confirmed
        view.fixture_button.setEnabled(True)

    def scan_serial(self) -> str:
        return self._call("serial")

    def confirm(self, question: str) -> bool:
        return bool(self._call("confirm", question))

    def show_outcome(self, serial: str, outcome: str, summary: str) -> None:
        self._call("outcome", serial, outcome, summary)


def _requires(name: str) -> tuple[str, ...]:
    try:
        from procedures import find_procedure

        return tuple(find_procedure(name).requires)
    except Exception:  # noqa: BLE001 - an unknown procedure is refused when it starts
        return ()


def run_operator(station: str | None, *, run: str | None, params: dict[str, str], seed: int = 0,
                 screenshot: str | None = None, operator_name: str = "") -> int:
    """Open the operator's window on a station (blocking until it closes); with `screenshot`, test
    one demo unit headless, save the window as a PNG and exit."""
    import os

    from .app import _app, has_display, make_backend

    if screenshot is None and not os.environ.get("QT_QPA_PLATFORM") and not has_display():
        raise SystemExit("gyrobench gui --operator: no display (DISPLAY / WAYLAND_DISPLAY unset); use --screenshot "
                         "FILE to run headless, or set QT_QPA_PLATFORM")
    app = _app()
    backend = make_backend(station, seed=seed)
    name = run or default_step(backend)
    view = OperatorView(backend, [(name, dict(params))], operator_name=operator_name)
    try:
        if screenshot is None:
            if backend.simulated:
                backend.set_speed(1.0)
            view.show()
            return int(app.exec())
        view.show()
        done = threading.Event()
        view.unit_finished.connect(lambda *_: done.set())
        view.serial_field.setText("DEMO-0001")
        view._serial_entered()
        view.fixture_button.click()
        if view.spin_button.isEnabled():
            view.spin_button.click()
        import time

        deadline = time.monotonic() + 600
        while not done.is_set() and time.monotonic() < deadline:
            app.processEvents()
            time.sleep(0.005)
        app.processEvents()
        view.grab().save(str(screenshot), "PNG")
        print(f"screenshot {screenshot}: unit {view.units_done[-1] if view.units_done else None}")
        return 0
    finally:
        backend.close()
        view.close()


def default_step(backend: Any) -> str:
    """A short demonstration step for a simulated station: a table spin when there is a table."""
    return "table-spin" if "table" in backend.station.config.devices else "mems-sweep"
