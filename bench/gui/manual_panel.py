"""The manual-control panel: start and end a manual session on an idle station, table rate and
stop, drive on and off, AGC setpoint, stream start and stop, each refused right at its field in
the engine's own words; and the safe-state button, which is also on the window's toolbar so it
is always reachable.  The session itself is the engine's (bench.engine.manual): this panel only
submits actions and shows `session.state`."""

from __future__ import annotations

import math
from typing import Any

from PySide6.QtCore import Qt, QTimer
from PySide6.QtGui import QAction
from PySide6.QtWidgets import (
    QDockWidget,
    QFormLayout,
    QGridLayout,
    QGroupBox,
    QHBoxLayout,
    QLabel,
    QLineEdit,
    QPushButton,
    QScrollArea,
    QSizePolicy,
    QVBoxLayout,
    QWidget,
)

from bench.engine.manual import AGC_SETPOINT, ManualSession

SAFE_STYLE = "QPushButton { background: #c00000; color: white; font-weight: bold; padding: 4px 10px; }"
ERROR_STYLE = "color: #c00000;"
INVALID_STYLE = "QLineEdit { background: #ffd6d6; border: 1px solid #c00000; }"
REFRESH_MS = 200


def _wrapping_label(text: str = "", style: str = "") -> QLabel:
    lab = QLabel(text)
    lab.setWordWrap(True)
    lab.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Preferred)
    lab.setStyleSheet(style)
    lab.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
    return lab


class ManualPanel(QWidget):
    """Controls of one manual session on the backend's station (EngineBackend with its mixin)."""

    def __init__(self, backend: Any, parent: QWidget | None = None, *, on_started: Any = None) -> None:
        super().__init__(parent)
        self.backend = backend
        self.session: ManualSession | None = None
        self._checker = ManualSession(backend.station)  # checks a field's text as the engine will
        self._pending: list[tuple[Any, QLabel]] = []  # submitted actions, and where a refusal is shown
        self._on_started = on_started
        max_rate = backend.station.limit("table", "max_rate_dps")

        lay = QVBoxLayout(self)
        self.state_label = _wrapping_label("manual control is off")
        self.state_label.setObjectName("manual_state")
        lay.addWidget(self.state_label)
        row = QHBoxLayout()
        self.start_button = QPushButton("Start manual control")
        self.end_button = QPushButton("End (safe state)")
        row.addWidget(self.start_button)
        row.addWidget(self.end_button)
        lay.addLayout(row)
        self.message = _wrapping_label("", ERROR_STYLE)  # why a session could not start
        lay.addWidget(self.message)

        table = QGroupBox("Rate table")
        tl = QGridLayout(table)
        limit = "" if max_rate is None else f" (limit \u00b1{max_rate:g})"
        tl.addWidget(QLabel(f"rate [deg/s]{limit}"), 0, 0, 1, 3)
        self.rate_edit = QLineEdit("0")
        self.rate_edit.setObjectName("manual_rate")
        self.rate_button = QPushButton("Set rate")
        self.stop_button = QPushButton("Stop table")
        tl.addWidget(self.rate_edit, 1, 0)
        tl.addWidget(self.rate_button, 1, 1)
        tl.addWidget(self.stop_button, 1, 2)
        self.rate_error = _wrapping_label("", ERROR_STYLE)
        tl.addWidget(self.rate_error, 2, 0, 1, 3)
        lay.addWidget(table)

        drive = QGroupBox("Drive (FPGA loops)")
        dl = QGridLayout(drive)
        self.drive_on_button = QPushButton("Drive on")
        self.drive_off_button = QPushButton("Drive off")
        dl.addWidget(self.drive_on_button, 0, 0)
        dl.addWidget(self.drive_off_button, 0, 1)
        dl.addWidget(QLabel(f"AGC setpoint ({AGC_SETPOINT.limit_text()})"), 1, 0, 1, 2)
        self.agc_edit = QLineEdit(f"{AGC_SETPOINT.default:g}")
        self.agc_edit.setObjectName("manual_agc")
        self.agc_button = QPushButton("Set setpoint")
        dl.addWidget(self.agc_edit, 2, 0)
        dl.addWidget(self.agc_button, 2, 1)
        self.agc_error = _wrapping_label("", ERROR_STYLE)
        dl.addWidget(self.agc_error, 3, 0, 1, 2)
        lay.addWidget(drive)

        stream = QGroupBox("Stream")
        sl = QHBoxLayout(stream)
        self.stream_start_button = QPushButton("Start stream")
        self.stream_stop_button = QPushButton("Stop stream")
        sl.addWidget(self.stream_start_button)
        sl.addWidget(self.stream_stop_button)
        lay.addWidget(stream)

        shown = QGroupBox("Now")
        fl = QFormLayout(shown)
        self.readings: dict[str, QLabel] = {}
        for key, label in (("rate_dps", "table rate [deg/s]"), ("rate_cmd_dps", "commanded [deg/s]"),
                           ("drive_on", "drive (read back)"), ("agc_setpoint", "AGC setpoint"), ("stream_on", "stream"),
                           ("last", "last action")):
            value = _wrapping_label("-")
            value.setObjectName(f"manual_{key}")
            self.readings[key] = value
            fl.addRow(label, value)
        lay.addWidget(shown)

        self.safe_button = QPushButton("SAFE STATE")
        self.safe_button.setObjectName("manual_safe_state")
        self.safe_button.setStyleSheet(SAFE_STYLE)
        self.safe_button.setToolTip("cut the drive, bring the table to rest, outputs off (always available)")
        lay.addWidget(self.safe_button)
        lay.addStretch(1)

        self.start_button.clicked.connect(self.start)
        self.end_button.clicked.connect(self.end)
        self.safe_button.clicked.connect(self.safe_state)
        self.rate_button.clicked.connect(lambda: self._submit("table_rate", self.rate_edit, self.rate_error))
        self.rate_edit.returnPressed.connect(self.rate_button.click)
        self.stop_button.clicked.connect(lambda: self._submit("table_stop", None, self.rate_error))
        self.drive_on_button.clicked.connect(lambda: self._submit("drive_on", None, self.agc_error))
        self.drive_off_button.clicked.connect(lambda: self._submit("drive_off", None, self.agc_error))
        self.agc_button.clicked.connect(lambda: self._submit("agc_setpoint", self.agc_edit, self.agc_error))
        self.agc_edit.returnPressed.connect(self.agc_button.click)
        self.stream_start_button.clicked.connect(lambda: self._submit("stream_start", None, self.message))
        self.stream_stop_button.clicked.connect(lambda: self._submit("stream_stop", None, self.message))
        self.rate_edit.textChanged.connect(lambda t: self._check_field("table_rate", self.rate_edit, self.rate_error))
        self.agc_edit.textChanged.connect(lambda t: self._check_field("agc_setpoint", self.agc_edit, self.agc_error))

        self.timer = QTimer(self)
        self.timer.setInterval(REFRESH_MS)
        self.timer.timeout.connect(self.refresh)
        self.timer.start()
        self.refresh()

    # --- operator ------------------------------------------------------------------------------
    def active(self) -> bool:
        return self.session is not None and self.session.state.active

    def start(self) -> bool:
        """Start a session (refused, with the reason shown, while a run holds the station)."""
        self.message.setText("")
        try:
            self.session = self.backend.start_manual()
        except (RuntimeError, ValueError) as exc:
            self.message.setText(str(exc))
            return False
        if self._on_started is not None:
            self._on_started()
        self.refresh()
        return True

    def end(self) -> None:
        """End the session; the engine brings the station to its safe state."""
        if self.session is not None:
            self.backend.end_manual()

    def safe_state(self) -> None:
        text = self.backend.safe_state_now("safe state button")
        self.message.setStyleSheet("color: #9a6200;")
        self.message.setText(text)
        self._safe_asked = True

    def _check_field(self, kind: str, edit: QLineEdit, error: QLabel) -> bool:
        try:
            self._checker.check(kind, edit.text())
        except ValueError as exc:
            edit.setStyleSheet(INVALID_STYLE)
            error.setText(str(exc))
            return False
        edit.setStyleSheet("")
        error.setText("")
        return True

    def _submit(self, kind: str, edit: QLineEdit | None, error: QLabel) -> None:
        """Check, then queue the action; a refusal (here or by the driver) is shown at `error`."""
        if edit is not None and not self._check_field(kind, edit, error):
            if self.active():  # refused here: the session still logs and records the refusal
                try:
                    self.session.submit(kind, edit.text())
                except ValueError:
                    pass
            return
        error.setStyleSheet(ERROR_STYLE)
        if self.session is None:
            error.setText(f"{kind}: start manual control first")
            return
        try:
            action = self.session.submit(kind, None if edit is None else edit.text())
        except ValueError as exc:
            error.setText(str(exc))
            return
        error.setText("")
        self._pending.append((action, error))

    # --- display ---------------------------------------------------------------------------------
    def refresh(self) -> None:
        """Show the session's state (read by the engine's thread) and the refusals of done actions
        (nothing to do while the dock is hidden: the window's redraws keep the CPU)."""
        self._show_safe_state_done()
        if not self.isVisible():
            return
        for action, error in list(self._pending):
            if action.done.is_set():
                self._pending.remove((action, error))
                if action.error:
                    error.setStyleSheet(ERROR_STYLE)
                    error.setText(action.error)
        active = self.active()
        busy = self.backend.running() and not active
        for w in (self.rate_button, self.stop_button, self.drive_on_button, self.drive_off_button,
                  self.agc_button, self.stream_start_button, self.stream_stop_button, self.end_button):
            w.setEnabled(active)
        self.start_button.setEnabled(not self.backend.running())
        if active:
            s = self.session.state
            self.state_label.setText(f"<b>manual control</b> (session {s.run_id}) at t = {s.t_s:.1f} s")
            shown = {"rate_dps": "-" if s.rate_dps is None else f"{s.rate_dps:.3f}",
                     "rate_cmd_dps": f"{s.rate_cmd_dps:g}", "drive_on": _drive_text(s.drive_read, s.drive_on),
                     "agc_setpoint": f"{s.agc_setpoint:g}", "stream_on": "on" if s.stream_on else "off",
                     "last": s.last or "-"}
        else:
            self.state_label.setText("a run holds the station" if busy else "manual control is off")
            shown = {k: "-" for k in self.readings}
        for key, text in shown.items():
            self.readings[key].setText(text)

    def _show_safe_state_done(self) -> None:
        """Replace "aborting to the safe state..." by what the engine confirmed, once it has."""
        if not getattr(self, "_safe_asked", False):
            return
        done = getattr(self.backend, "safe_state_done", None)
        result = done() if done is not None else None
        if result is None:
            return
        self._safe_asked = False
        ok, text = result
        self.message.setStyleSheet("" if ok else ERROR_STYLE)
        self.message.setText(text)

    def table_rate_shown(self) -> float:
        """The table rate the panel shows (NaN when none)."""
        text = self.readings["rate_dps"].text()
        try:
            return float(text)
        except ValueError:
            return math.nan


def _drive_text(read: bool | None, commanded: bool) -> str:
    """The drive as the FPGA reports it, and the command when they differ."""
    if read is None:
        return "-"
    text = "on" if read else "off"
    return text if read == commanded else f"{text} (commanded {'on' if commanded else 'off'})"


class ManualDock(QDockWidget):
    """The panel in a dock; closing it ends the session (the station goes to its safe state)."""

    def __init__(self, panel: ManualPanel, parent: QWidget | None = None) -> None:
        super().__init__("Manual control", parent)
        self.setObjectName("manual_dock")
        self.panel = panel
        scroll = QScrollArea()  # on a small screen the panel scrolls; it never makes the window taller
        scroll.setWidget(panel)
        scroll.setWidgetResizable(True)
        scroll.setFrameShape(QScrollArea.Shape.NoFrame)
        scroll.setHorizontalScrollBarPolicy(Qt.ScrollBarPolicy.ScrollBarAlwaysOff)
        self.setWidget(scroll)

    def closeEvent(self, event) -> None:  # noqa: N802 - Qt's name
        self.panel.end()
        super().closeEvent(event)


def install(window: Any) -> ManualDock | None:
    """Add manual control to the main window: a dock (hidden until asked for), a "Manual control"
    toolbar button and menu entry, and a SAFE STATE toolbar button that is always there.  A
    backend without manual control (a replay) gets only nothing."""
    backend = window.backend
    if not hasattr(backend, "start_manual"):
        return None

    def realtime() -> None:  # an operator acts in real time: a simulated clock at "max" would race away
        if backend.simulated and math.isinf(float(window.station.speed.currentData())):
            window.station.set_speed(1.0)

    panel = ManualPanel(backend, on_started=realtime)
    dock = ManualDock(panel, window)
    window.addDockWidget(Qt.DockWidgetArea.RightDockWidgetArea, dock)
    dock.hide()
    bar = window.addToolBar("Station")
    bar.setObjectName("station_toolbar")
    bar.setMovable(False)
    show = QAction("Manual control", window)
    show.setObjectName("manual_action")
    show.triggered.connect(lambda: (dock.show(), dock.raise_()))
    bar.addAction(show)
    safe = QPushButton("SAFE STATE")
    safe.setObjectName("toolbar_safe_state")
    safe.setStyleSheet(SAFE_STYLE)
    safe.setToolTip(panel.safe_button.toolTip())

    def safe_now() -> None:
        panel.safe_state()
        if window.run_active:  # a run or a session: aborted, the status line says so like Abort does
            window.aborting = True
            window.set_status_line("aborting: waiting for the safe state...", "amber")

    safe.clicked.connect(safe_now)
    panel.safe_button.clicked.disconnect()
    panel.safe_button.clicked.connect(safe_now)
    bar.addWidget(safe)
    window.manual_dock = dock
    window.safe_state_button = safe
    return dock
