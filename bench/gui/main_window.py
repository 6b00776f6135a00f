"""The lab engineer's main window: station, procedure and parameters, Start/Pause/Abort, steps,
live plots, log and results, all fed by the engine's events through the bridge."""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

from PySide6.QtCore import Qt
from PySide6.QtGui import QAction
from PySide6.QtWidgets import (
    QApplication,
    QComboBox,
    QFileDialog,
    QGroupBox,
    QHBoxLayout,
    QLabel,
    QMainWindow,
    QMessageBox,
    QProgressBar,
    QPushButton,
    QScrollArea,
    QSizePolicy,
    QSplitter,
    QVBoxLayout,
    QWidget,
)

from bench.engine import events as ev

from .backend import GuiBackend
from .bridge import EventBridge
from .panels import LogPane, ResultsTable, StationPanel, StepList, plots_over_tabs
from .param_form import ParameterForm
from .plots import LivePlots

GIL_SWITCH_S = 0.0005
CLOSE_WAIT_S = 120.0  # closing during a run waits this long for its safe state (then backend.close waits on)
STATUS_STYLES = {"green": "color: #1a6b1a; font-weight: bold;", "red": "color: #c00000; font-weight: bold;",
                 "amber": "color: #9a6200; font-weight: bold;", "neutral": ""}


def _duration(seconds: float) -> str:
    """12.3 s, 4 min 05 s, 2 h 03 min."""
    if seconds < 60:
        return f"{seconds:.1f} s"
    if seconds < 3600:
        return f"{int(seconds // 60)} min {int(seconds % 60):02d} s"
    return f"{int(seconds // 3600)} h {int(seconds % 3600 // 60):02d} min"


def outcome_colour(outcome: str) -> str:
    """Green only for a run that completed or passed; red for ERROR/FAIL/INTERRUPTED; amber for the rest."""
    if outcome in ("COMPLETE", "PASS"):
        return "green"
    if outcome in ("ERROR", "FAIL", "INTERRUPTED"):
        return "red"
    return "amber"

LOCKSTEP_WAIT_S = 0.25  # longest the bridge holds a lockstep engine per event
LOCKSTEP_DRAIN_GAP_S = 0.025  # the bridge's drains at least this far apart in lockstep (its queue half full: at once)
LABELS_EVERY_S = 0.1  # the time and progress labels' update period (wall)
MAX_SPEED_LABELS_EVERY_S = 0.25  # ... at "max" (a progress bar repaints at once when set: ~2 ms each)
MAX_SPEED_REFRESH_HZ = 5.0  # plot redraws a second at "max" speed (benchmarks/gui_max_speed.py)
STATUS_LINES = 2  # the status box's height in lines: a longer status scrolls inside it
STATION_TREE_PX = 260  # the station's device tree: every device's rows without scrolling
STEPS_PX = 120  # the step list's fixed height (it scrolls)


def _wall_s() -> float:
    """Wall clock of the label throttle (a test replaces it)."""
    return time.monotonic()


def _fixed_text_box(label: QLabel, lines: int) -> QScrollArea:
    """`label` (word-wrapped, its full text kept) in a frameless box `lines` lines high that
    scrolls: a long message never grows the column, moves the buttons or overlaps anything."""
    box = QScrollArea()
    box.setWidget(label)
    box.setWidgetResizable(True)
    box.setFrameShape(QScrollArea.Shape.NoFrame)
    box.setHorizontalScrollBarPolicy(Qt.ScrollBarPolicy.ScrollBarAlwaysOff)
    label.setAlignment(Qt.AlignmentFlag.AlignTop | Qt.AlignmentFlag.AlignLeft)
    label.setContentsMargins(0, 0, 0, 0)
    label.setMargin(0)
    box.setFixedHeight(lines * label.fontMetrics().lineSpacing())  # whole lines: no sliver of the next
    return box


class MainWindow(QMainWindow):
    """One station, one run at a time; everything the engine says arrives as events."""

    def __init__(self, backend: GuiBackend, parent: QWidget | None = None, *, refresh_hz: float = 25.0) -> None:
        super().__init__(parent)
        # the engine thread is CPU-bound at "max" speed and PySide releases the GIL around every Qt
        # call: with the default 5 ms switch interval each call of the GUI thread can wait that long
        # to get it back (a convoy), and the window stutters; 0.5 ms keeps it fluid.
        sys.setswitchinterval(min(sys.getswitchinterval(), GIL_SWITCH_S))
        self.backend = backend
        self.setWindowTitle(f"gyrobench - {backend.station_name}")
        self.resize(1280, 860)
        self.run_active = False
        self.paused = False
        self.aborting = False
        self.last_finished: ev.RunFinished | None = None
        self.t_sim_s = 0.0
        self.screenshot_t_s: float | None = None
        self.run_unit: tuple[list[str], str] = ([], "")  # the serials and operator of the run going on

        self.station = StationPanel(backend.station_name, backend.simulated)
        self.station.speed_changed.connect(self._on_speed)
        self.procedure = QComboBox()
        self.procedure.setObjectName("procedure")
        self.procedure.addItems(list(backend.procedures()))  # only what this station can run
        hidden = backend.unavailable() if hasattr(backend, "unavailable") else {}
        if hidden:
            why = "; ".join(f"{n} ({w})" for n, w in hidden.items())
            self.procedure.setToolTip(f"not offered on this station: {why}")
        self.form = ParameterForm()
        from .unit_fields import UnitFields

        self.unit = UnitFields()  # DUT serial and operator: every run is stored with them
        self.unit.scanned.connect(lambda _s: self.start_button.setFocus())
        self.start_button = QPushButton("Start")
        self.pause_button = QPushButton("Pause")
        self.abort_button = QPushButton("Abort")
        self.abort_button.setStyleSheet("QPushButton:enabled { background: #c00000; color: white; font-weight: bold; }")
        self.safe_label = QLabel("")
        self.status_line = QLabel("ready")  # what the run is doing / how it ended, in its colour
        self.status_line.setObjectName("status_line")
        for lab in (self.safe_label, self.status_line):
            lab.setWordWrap(True)  # a long error wraps: it never widens the window
            lab.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Preferred)
            lab.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        self.steps = StepList()
        self.run_info = QLabel("no run")  # run id, elapsed, whole-run progress, time left
        self.run_info.setObjectName("run_info")
        self.run_info.setWordWrap(True)
        self.run_progress = QProgressBar()
        self.run_progress.setRange(0, 1000)
        self.run_progress.setFormat("run %p%")
        self.run_t0_s = 0.0
        self.run_id = ""
        self.steps_done = 0
        self.step_fraction = 0.0
        self.refresh_hz = refresh_hz
        self._labels_wall_s = 0.0  # when the time and progress labels were last set
        self.labels_every_s = LABELS_EVERY_S  # their period now (MAX_SPEED_LABELS_EVERY_S at "max")
        self._progress: tuple[float, str] | None = None  # the step's progress not yet shown (fraction, message)
        from PySide6.QtCore import QTimer

        self._labels_timer = QTimer(self)  # a batch that skipped the labels: they follow within LABELS_EVERY_S
        self._labels_timer.setSingleShot(True)
        self._labels_timer.setInterval(int(LABELS_EVERY_S * 1000))
        self._labels_timer.timeout.connect(lambda: self.flush_labels())
        self.plots = LivePlots(refresh_hz=refresh_hz)
        self.log = LogPane()
        self.results = ResultsTable()

        # the left column: the procedure with ALL its parameter fields, then the station's devices,
        # scroll together (a run scrolls to the station: the form is locked then); the speed, the
        # buttons, the status and the steps sit below in a fixed place (a long status scrolls
        # inside its own fixed box: nothing moves, nothing overlaps)
        left = QWidget()
        left_lay = QVBoxLayout(left)
        left_lay.setContentsMargins(4, 4, 4, 4)
        proc_box = QGroupBox("Procedure")
        proc_lay = QVBoxLayout(proc_box)
        proc_lay.addWidget(self.unit)
        proc_lay.addWidget(self.procedure)
        proc_lay.addWidget(self.form)  # every field at its full height: the column scrolls, not the form
        left_lay.addWidget(proc_box)
        self.station_box = QGroupBox("Station")
        QVBoxLayout(self.station_box).addWidget(self.station)
        self.station.tree.setMinimumHeight(STATION_TREE_PX)
        left_lay.addWidget(self.station_box)
        left_lay.addStretch(1)
        left.setMinimumWidth(320)
        left.setMaximumWidth(420)
        left_scroll = QScrollArea()
        left_scroll.setObjectName("left_column")
        left_scroll.setWidget(left)
        left_scroll.setWidgetResizable(True)
        left_scroll.setFrameShape(QScrollArea.Shape.NoFrame)
        left_scroll.setHorizontalScrollBarPolicy(Qt.ScrollBarPolicy.ScrollBarAlwaysOff)
        self.left_scroll = left_scroll

        controls = QWidget()
        controls.setObjectName("run_controls")
        ctl_lay = QVBoxLayout(controls)
        ctl_lay.setContentsMargins(4, 2, 4, 2)
        speed_row = QHBoxLayout()  # the station's clock speed and time, always in view (not in the panel)
        for lab in self.station.findChildren(QLabel):
            if lab.text() == "speed":
                lab.hide()
        speed_row.addWidget(QLabel("speed"))
        speed_row.addWidget(self.station.speed)
        speed_row.addWidget(self.station.sim_time, 1)
        ctl_lay.addLayout(speed_row)
        buttons = QHBoxLayout()
        for b in (self.start_button, self.pause_button, self.abort_button):
            buttons.addWidget(b)
        ctl_lay.addLayout(buttons)
        self.status_box = _fixed_text_box(self.status_line, STATUS_LINES)
        ctl_lay.addWidget(self.status_box)
        self.safe_label.setWordWrap(False)
        self.safe_label.setFixedHeight(self.safe_label.fontMetrics().lineSpacing() + 4)
        ctl_lay.addWidget(self.safe_label)
        step_box = QGroupBox("Steps")
        step_lay = QVBoxLayout(step_box)
        self.run_info.setFixedHeight(3 * self.run_info.fontMetrics().lineSpacing() + 4)
        self.run_info.setAlignment(Qt.AlignmentFlag.AlignTop | Qt.AlignmentFlag.AlignLeft)
        step_lay.addWidget(self.run_info)
        step_lay.addWidget(self.run_progress)
        self.steps.setFixedHeight(STEPS_PX)
        step_lay.addWidget(self.steps)

        column = QWidget()
        column.setObjectName("left_panel")
        col_lay = QVBoxLayout(column)
        col_lay.setContentsMargins(0, 0, 0, 0)
        col_lay.setSpacing(2)
        col_lay.addWidget(left_scroll, 1)
        col_lay.addWidget(controls)
        col_lay.addWidget(step_box)
        column.setMinimumWidth(340)
        column.setMaximumWidth(440)

        right, self.tabs = plots_over_tabs(self.plots, self.results, self.log)
        central = QSplitter(Qt.Orientation.Horizontal)
        central.addWidget(column)
        central.addWidget(right)
        central.setStretchFactor(1, 1)
        self.setCentralWidget(central)

        open_action = QAction("&Open recorded run...", self)
        open_action.triggered.connect(self._open_dialog)
        file_menu = self.menuBar().addMenu("&File")
        file_menu.addAction(open_action)
        self.history_action = QAction("Run &history...", self)
        self.history_action.triggered.connect(self.open_history)
        file_menu.addAction(self.history_action)
        self.export_action = QAction("&Export...", self)
        self.export_action.triggered.connect(lambda: self.export_dialog())
        file_menu.addAction(self.export_action)
        from .export import add_plot_menus

        add_plot_menus(self.plots, self.export_dialog)
        self.side_windows: list[QWidget] = []  # history browser, replays, export and report dialogs
        self.statusBar().showMessage("ready")

        self.procedure.currentTextChanged.connect(self._on_procedure)
        self.form.validity_changed.connect(lambda _v: self._update_buttons())
        self.start_button.clicked.connect(self.start)
        self.pause_button.clicked.connect(self.toggle_pause)
        self.abort_button.clicked.connect(self.abort)
        self.results.report_button.clicked.connect(self._open_report)

        self.bridge = EventBridge(backend.bus, self)
        self.bridge.events.connect(self.on_events)
        self._set_backpressure(float(self.station.speed.currentData()))
        self._on_procedure(self.procedure.currentText())
        from .manual_panel import install as install_manual

        install_manual(self)  # the manual-control dock and the SAFE STATE button always on the toolbar
        if hasattr(backend, "start_polling"):
            backend.start_polling()  # the station panel from the devices, also between runs

    # --- controls --------------------------------------------------------------------------
    def _on_procedure(self, name: str) -> None:
        self.form.set_specs(self.backend.procedures().get(name, ()))
        self._update_buttons()

    def _update_buttons(self) -> None:
        self.start_button.setEnabled(self.form.is_valid() and not self.run_active)
        self.form.setEnabled(not self.run_active)
        self.procedure.setEnabled(not self.run_active)
        self.unit.set_running(self.run_active)
        self.pause_button.setEnabled(self.run_active)
        self.pause_button.setText("Resume" if self.paused else "Pause")
        self.abort_button.setEnabled(self.run_active)

    def _on_speed(self, speed: float) -> None:
        if self.backend.simulated:
            self.backend.set_speed(speed)
        self._set_backpressure(speed)

    def _set_backpressure(self, speed: float) -> None:
        """Hold the engine for the window only in lockstep on a simulated station (nothing is
        lost there: the world waits); in real time or on a real bench, never."""
        lockstep = self.backend.simulated and math.isinf(speed)
        self.bridge.max_wait_s = LOCKSTEP_WAIT_S if lockstep else 0.0
        self.bridge.min_gap_s = LOCKSTEP_DRAIN_GAP_S if lockstep else 0.0  # fewer, fuller drains at "max"
        # at "max" a frame's Python painting competes with the engine for the interpreter: fewer frames
        self.plots.set_refresh_hz(MAX_SPEED_REFRESH_HZ if lockstep else self.refresh_hz)
        self.labels_every_s = MAX_SPEED_LABELS_EVERY_S if lockstep else LABELS_EVERY_S
        self._labels_timer.setInterval(int(self.labels_every_s * 1000))

    def set_status_line(self, text: str, colour: str) -> None:
        """The line under the buttons (and the status bar): `colour` is one of STATUS_COLOURS."""
        self.status_line.setText(text)
        self.status_line.setToolTip(text if len(text) > 60 else "")
        self.status_line.setStyleSheet(STATUS_STYLES[colour])
        self.statusBar().showMessage(text.splitlines()[0][:200] if text else "")

    def start(self) -> None:
        """Start the selected procedure with the form's values (refused while one is invalid)."""
        if not self.form.validate() or self.run_active:
            return
        try:
            duts, operator = self.unit.checked()
            if hasattr(self.backend, "set_unit"):
                self.backend.set_unit(duts, operator)
            self.unit.remember()
            self.run_unit = (duts, operator)
            self.backend.start(self.procedure.currentText(), self.form.values())
        except (ValueError, RuntimeError) as exc:
            self.log.add(self.t_sim_s, "ERROR", str(exc))
            self.set_status_line(f"not started: {exc}", "red")
            return
        self.run_active = True
        self.paused = False
        self.aborting = False
        self.safe_label.setText("")
        self.set_status_line("running", "neutral")
        self._update_buttons()

    def toggle_pause(self) -> None:
        if not self.run_active:
            return
        if self.paused:
            self.backend.resume()
        else:
            self.backend.pause()
        self.paused = not self.paused
        if self.paused:
            self.set_status_line("Paused \u2014 the table keeps its rate", "amber")
        else:
            self.set_status_line("running", "neutral")
        self._update_buttons()

    def abort(self) -> None:
        if self.run_active:
            self.backend.abort()
            self.aborting = True
            self.set_status_line("aborting: waiting for the safe state...", "amber")

    # --- events ----------------------------------------------------------------------------
    def on_events(self, batch: list[ev.Event]) -> None:
        """GUI thread: apply a batch of engine events to the widgets.  Sample blocks are joined
        per stream (one numpy pass per stream per batch however fast the engine runs); they are
        flushed before a run starts or ends, where the plots' state changes."""
        for e in batch:
            self.t_sim_s = max(self.t_sim_s, e.t_sim_s)
            if isinstance(e, ev.SampleBlock):
                self.plots.queue_samples(e.stream, tuple(e.columns), e.data)
                continue
            if isinstance(e, (ev.RunStarted, ev.RunFinished)):
                self.plots.flush_samples()
                self._apply_progress()
            if isinstance(e, ev.RunFinished):
                self.plots.fit_time_axes()  # the run's whole record, edge to edge
            if isinstance(e, ev.FitUpdate):
                self.plots.set_fit(e.name, e.curves)
            elif isinstance(e, ev.StreamDeclared):
                self.plots.declare(e.schema)
            elif isinstance(e, ev.Progress):
                self._progress = (e.fraction, e.message)  # the step's bar follows with the labels (a
                self.step_fraction = min(1.0, max(0.0, e.fraction))  # bar's repaint each event costs)
            elif isinstance(e, ev.StepStarted):
                self._apply_progress()
                self.steps.set_status(e.name, "running")
                if not self.paused and not self.aborting:
                    self.set_status_line(f"step {e.index + 1}/{e.total}: {e.title or e.name}", "neutral")
            elif isinstance(e, ev.StepFinished):
                self._apply_progress()
                self.steps.set_status(e.name, e.status)
                self.steps_done += 1
                self.step_fraction = 0.0
            elif isinstance(e, ev.Measurement):
                self.results.add(e.name, e.value, e.unit, e.low, e.high, e.outcome, e.dut, ci95=e.ci95)
            elif isinstance(e, ev.Log):
                self.log.add(e.t_sim_s, e.level, e.message)
                if self.run_active and e.message.startswith(("safe state confirmed", "safe state NOT confirmed")):
                    self._on_safe_state_report(e.message.startswith("safe state confirmed"))
            elif isinstance(e, ev.StationStatus):
                self.station.update_devices(e.devices)
            elif isinstance(e, ev.RunStarted):
                self._on_run_started(e)
            elif isinstance(e, ev.RunFinished):
                self._on_run_finished(e)
        now = _wall_s()
        if now - self._labels_wall_s >= self.labels_every_s or not self.run_active:  # a label a batch would cost
            self.flush_labels(now)  # more than the plots at "max" speed: ten times a second is enough
        elif not self._labels_timer.isActive():  # the last batch's time is shown within LABELS_EVERY_S
            self._labels_timer.start()

    def flush_labels(self, now: float | None = None) -> None:
        """Show the bench time and the run's progress as of the last event (a screenshot calls it)."""
        self._labels_wall_s = _wall_s() if now is None else now
        self._apply_progress()
        self.station.set_time(self.t_sim_s)
        if self.run_active:
            self._show_run_info()

    def _on_safe_state_report(self, confirmed: bool) -> None:
        """The engine's safe-state report, shown at once (the run's files close after it, then
        RunFinished): the operator never waits on a confirmation the engine already gave."""
        self.safe_label.setText("safe state confirmed" if confirmed else "SAFE STATE NOT CONFIRMED")
        self.safe_label.setStyleSheet(STATUS_STYLES["neutral"] if confirmed else STATUS_STYLES["red"])
        if self.aborting:
            self.set_status_line("aborted: safe state confirmed; closing the run's files..." if confirmed
                                 else "aborted: SAFE STATE NOT CONFIRMED", "amber" if confirmed else "red")

    def _apply_progress(self) -> None:
        """The step's last reported progress to its bar (with the labels, and before a step changes)."""
        if self._progress is not None:
            self.steps.set_progress(*self._progress)
            self._progress = None

    def run_fraction(self) -> float:
        """The whole run's progress: finished steps plus the current one's fraction, over all
        steps (the engine declares no step durations: each step counts the same)."""
        n = max(1, self.steps.tree.topLevelItemCount())
        return min(1.0, (self.steps_done + self.step_fraction) / n)

    def _show_run_info(self) -> None:
        elapsed = max(0.0, self.t_sim_s - self.run_t0_s)
        frac = self.run_fraction()
        self.run_progress.setValue(int(round(1000 * frac)))
        left = "time left: estimating..."
        if self.run_active and 0.02 < frac < 1.0 and elapsed > 0:
            left = f"about {_duration(elapsed * (1.0 - frac) / frac)} left (from the progress)"
        elif not self.run_active:
            left = "finished"
        self.run_info.setText(f"run {self.run_id}  \u00b7  elapsed {_duration(elapsed)}  \u00b7  {left}")

    def _run_bryan_factor(self, params: dict) -> float | None:
        """The run's K (its bryan_factor, 0: the station's nominal), for the live rate output."""
        k = params.get("bryan_factor")
        if isinstance(k, (int, float)) and k > 0:
            return float(k)
        station = getattr(self.backend, "station", None)
        try:
            return float(station.nominal()["bryan_factor"])
        except Exception:  # noqa: BLE001 - no station (a replay), or a kind without K: the wave's rate, said
            return None

    def _on_run_started(self, e: ev.RunStarted) -> None:
        from .plots import layout_for

        self.plots.set_layout(layout_for(e.procedure))  # the plots follow the procedure
        self.plots.clear()
        self.plots.set_bryan_factor(self._run_bryan_factor(e.params))
        self.plots.set_origin(e.t_sim_s if e.t_sim_s > 0 else None)  # a replay's RunStarted says 0
        self.run_t0_s = e.t_sim_s
        self.run_id = e.run_id
        self.safe_label.setText("")  # the last run's safe state is not this one's (manual control starts here too)
        self.steps_done = 0
        self.step_fraction = 0.0
        self.results.clear()
        from procedures import measurement_periods, no_truth_reasons

        from .run_truth import truth_for_run

        self.results.set_truth(truth_for_run(self.backend, e.procedure, e.run_id),  # the truth column (simulated)
                               measurement_periods(e.procedure), no_truth_reasons(e.procedure))
        self.steps.set_steps(e.steps)
        self.left_scroll.ensureWidgetVisible(self.station_box, 0, 0)  # the locked form gives way to the station
        self.run_active = True
        self.last_finished = None
        duts, operator = self.run_unit
        who = f" (DUT {', '.join(duts) or 'none'}, operator {operator or 'none'})"
        self.log.add(e.t_sim_s, "INFO", f"run {e.run_id} started: {e.procedure} {e.params}{who}")
        self._update_buttons()

    def _on_run_finished(self, e: ev.RunFinished) -> None:
        self.run_active = False
        self.paused = False
        self.aborting = False
        self.last_finished = e
        self.results.set_outcome(e.outcome, e.safe_state, e.end_reason)
        self.results.set_report(e.raw_file if e.raw_file and Path(e.raw_file).exists() else None)
        self.safe_label.setText("safe state confirmed" if e.safe_state else "SAFE STATE NOT CONFIRMED")
        self.safe_label.setStyleSheet(STATUS_STYLES["neutral"] if e.safe_state else STATUS_STYLES["red"])
        level = "ERROR" if outcome_colour(e.outcome) == "red" else "INFO"
        self.log.add(e.t_sim_s, level, f"run {e.run_id} finished: {e.outcome} ({e.end_reason})")
        self.set_status_line(f"{e.outcome}: {e.end_reason}" if e.end_reason else e.outcome, outcome_colour(e.outcome))
        self.plots.refresh(force=True)
        self._show_run_info()
        self._update_buttons()

    # --- replay and report -----------------------------------------------------------------
    def _open_dialog(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self, "Open recorded run", "runs", "HDF5 runs (*.h5 *.hdf5)")
        if path:
            self.open_run(path)

    def open_run(self, path: str) -> QWidget:
        """Replay a recorded run in its own window (its plots, results, log, recorded station and
        parameters; never mixed with the live station's); a corrupt or incomplete file says so there."""
        from .replay_view import ReplayWindow

        win = ReplayWindow(path)
        win.show()
        self.side_windows.append(win)
        self.statusBar().showMessage(f"replay of {path} opened in its own window")
        return win

    def open_history(self) -> QWidget:
        """The history browser over this station's results store."""
        from .history import HistoryBrowser

        store = getattr(getattr(self.backend, "runner", None), "store", None)
        win = HistoryBrowser(store.url if store is not None else None)
        win.show()
        self.side_windows.append(win)
        return win

    def export_dialog(self, title: str | None = None) -> QWidget:
        """File > Export... (or a plot's menu): a plot's recorded data (CSV, HDF5) or its figure (PNG, SVG)."""
        from .export import ExportDialog

        fin = self.last_finished
        raw = fin.raw_file if fin is not None and fin.raw_file and Path(fin.raw_file).exists() else None
        dialog = ExportDialog(self.plots, raw, self, title)
        dialog.open()
        return dialog

    def render_report(self) -> str | None:
        """Write the HTML report of the shown run next to its raw file; its path."""
        raw = self.results.report_path
        if not raw:
            return None
        from bench.recorder import open_run
        from bench.reporting import render_html

        out = Path(raw).with_suffix(".html")
        with open_run(raw) as data:
            out.write_text(render_html(data, None))
        return str(out)

    def _open_report(self) -> None:
        try:
            path = self.render_report()
        except (OSError, RuntimeError, KeyError, ValueError) as exc:
            self.log.add(self.t_sim_s, "ERROR", f"report failed: {exc}")
            return
        if path:
            from .open_report import open_in_browser

            dialog = open_in_browser(path, self)  # no browser here: says so with the path and a Copy button
            if dialog is not None:
                self.side_windows.append(dialog)

    def ask_close_during_run(self) -> bool:
        """Ask before closing during a run (tests replace QMessageBox.question)."""
        answer = QMessageBox.question(
            self, "gyrobench", "A run is going on. Abort it (the station goes to its safe state) and close?",
            QMessageBox.StandardButton.Yes | QMessageBox.StandardButton.No, QMessageBox.StandardButton.No)
        return answer == QMessageBox.StandardButton.Yes

    def quit_for_signal(self, name: str) -> None:
        """Ctrl+C or SIGTERM: abort a run to the safe state (no question), then close."""
        self.log.add(self.t_sim_s, "WARNING", f"{name}: aborting to the safe state and closing")
        self.quitting = True
        self.close()

    def closeEvent(self, event) -> None:  # noqa: N802 - Qt's name
        if self.run_active or self.backend.running():
            if self.run_active:  # after RunFinished the thread only says its last words: no question
                if not getattr(self, "quitting", False) and not self.ask_close_during_run():
                    event.ignore()
                    return
                self.abort()
            deadline = time.monotonic() + CLOSE_WAIT_S
            while self.backend.running() and time.monotonic() < deadline:  # the run's own safe state
                QApplication.processEvents()
                time.sleep(0.01)
            self.bridge.drain()
        if hasattr(self.backend, "stop_polling"):
            self.backend.stop_polling()
        self.bridge.detach()
        for win in self.side_windows:
            win.close()
        self.plots.shutdown()
        super().closeEvent(event)
