"""Replay of a recorded run in its own window: its own plots, results, log, recorded station and
parameters (with units), never mixed with the live station's.  A banner says plainly when the
raw file is incomplete (an interrupted or aborted run) or cannot be read (truncated, corrupt)."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import h5py
import numpy as np
from PySide6.QtCore import Qt
from PySide6.QtGui import QAction
from PySide6.QtWidgets import (
    QGroupBox,
    QHeaderView,
    QLabel,
    QMainWindow,
    QSizePolicy,
    QSplitter,
    QTableWidget,
    QTableWidgetItem,
    QTreeWidget,
    QTreeWidgetItem,
    QVBoxLayout,
    QWidget,
)

from bench.engine import events as ev

from .panels import LogPane, ResultsTable, plots_over_tabs
from .plots import LivePlots

BANNER_STYLES = {"red": "background: #f4c7c3; color: #8b0000; font-weight: bold; padding: 6px;",
                 "amber": "background: #fde9b8; color: #6b4a00; font-weight: bold; padding: 6px;",
                 "green": "background: #d3ecd3; color: #1a5c1a; padding: 6px;"}


@dataclass
class Recorded:
    """What a raw file holds for a replay, or why it cannot be replayed (`error`)."""

    path: Path
    events: list[ev.Event] = field(default_factory=list)
    attrs: dict[str, Any] = field(default_factory=dict)
    params: list[tuple[str, str, str]] = field(default_factory=list)  # name, value, unit
    incomplete: str | None = None
    error: str | None = None


def _decoded(value: Any) -> Any:
    if isinstance(value, bytes):
        value = value.decode("utf-8", "replace")
    if isinstance(value, str) and value[:1] in "{[":
        try:
            return json.loads(value)
        except ValueError:
            return value
    return value.item() if isinstance(value, np.generic) else value


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


def load_recorded(path: str | Path) -> Recorded:
    """Read a raw file for the replay view; never raises: a file that cannot be read comes back
    with `error`, one that holds less than a whole run with `incomplete`."""
    from .replay import replay_events

    rec = Recorded(Path(path))
    if not rec.path.exists():
        rec.error = f"{rec.path} does not exist"
        return rec
    try:
        with h5py.File(rec.path, "r", locking=False) as f:
            rec.attrs = {k: _decoded(v) for k, v in f.attrs.items()}
            if "parameters" in f:
                for name, ds in f["parameters"].items():
                    value = _decoded(ds[()])
                    unit = str(_decoded(ds.attrs.get("units", "")))
                    if unit == "1" and not isinstance(value, (int, float)) or isinstance(value, bool):
                        unit = ""  # a choice or a switch has no unit ("1" is the recorder's "none")
                    rec.params.append((name, f"{value:.10g}" if isinstance(value, float) else str(value), unit))
    except (OSError, RuntimeError, KeyError, ValueError) as exc:
        rec.error = (f"{rec.path.name} is not a readable HDF5 file (truncated or corrupt): {_first_line(exc)}. "
                     f"Nothing from it is shown.")
        return rec
    if not rec.params:
        params = rec.attrs.get("params")
        for name, value in (params.items() if isinstance(params, dict) else ()):
            rec.params.append((name, str(value), ""))
    try:
        rec.events = replay_events(rec.path)
    except (OSError, RuntimeError, KeyError, ValueError, TypeError) as exc:
        rec.error = f"{rec.path.name} cannot be replayed (truncated or corrupt): {_first_line(exc)}"
        return rec
    if "outcome" not in rec.attrs:
        rec.incomplete = "the run did not finish (the process was killed or is still running)"
    elif rec.attrs.get("incomplete"):
        rec.incomplete = str(rec.attrs["incomplete"])
    elif rec.attrs.get("outcome") in ("ERROR", "ABORTED", "INTERRUPTED"):
        rec.incomplete = f"the run ended {rec.attrs['outcome']} ({rec.attrs.get('end_reason', '')})"
    return rec


def _fill_tree(tree: QTreeWidget, value: Any, parent: QTreeWidgetItem | None = None, key: str = "") -> None:
    if isinstance(value, dict):
        node = parent
        if key:
            node = QTreeWidgetItem([key, ""])
            (parent.addChild(node) if parent is not None else tree.addTopLevelItem(node))
        for k, v in value.items():
            _fill_tree(tree, v, node, str(k))
        return
    item = QTreeWidgetItem([key, str(value)])
    (parent.addChild(item) if parent is not None else tree.addTopLevelItem(item))


class ReplayWindow(QMainWindow):
    """One recorded run, on its own: plots, results, log, recorded station and parameters."""

    def __init__(self, path: str | Path, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setAttribute(Qt.WidgetAttribute.WA_DeleteOnClose, False)
        self.resize(1280, 860)
        self.recorded = load_recorded(path)
        self.raw_file: str | None = None if self.recorded.error else str(self.recorded.path)
        rec = self.recorded
        run_id = str(rec.attrs.get("run_id", rec.path.stem))
        self.setWindowTitle(f"gyrobench - replay of {run_id}")

        self.banner = QLabel("")
        self.banner.setObjectName("replay_banner")
        self.banner.setWordWrap(True)
        self.banner.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Preferred)
        self.banner.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        self.identity = QLabel("")
        self.identity.setWordWrap(True)
        self.identity.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        self.params = QTableWidget(0, 3)
        self.params.setHorizontalHeaderLabels(("parameter", "value", "unit"))
        self.params.verticalHeader().setVisible(False)
        self.params.verticalHeader().setDefaultSectionSize(22)
        head = self.params.horizontalHeader()  # name and unit as wide as they need, the value takes the rest
        head.setSectionResizeMode(0, QHeaderView.ResizeMode.ResizeToContents)
        head.setSectionResizeMode(1, QHeaderView.ResizeMode.Stretch)
        head.setSectionResizeMode(2, QHeaderView.ResizeMode.ResizeToContents)
        self.params.setHorizontalScrollBarPolicy(Qt.ScrollBarPolicy.ScrollBarAlwaysOff)
        self.station = QTreeWidget()
        self.station.setHeaderLabels(("recorded station", ""))
        self.plots = LivePlots()
        self.results = ResultsTable()
        self.results.report_button.clicked.connect(self.open_report)
        self.log = LogPane()
        self.report_dialog = None

        left = QWidget()
        lay = QVBoxLayout(left)
        run_box = QGroupBox("Recorded run")
        QVBoxLayout(run_box).addWidget(self.identity)
        lay.addWidget(run_box)
        par_box = QGroupBox("Parameters")
        QVBoxLayout(par_box).addWidget(self.params)
        lay.addWidget(par_box, 2)
        st_box = QGroupBox("Station (as recorded)")
        QVBoxLayout(st_box).addWidget(self.station)
        lay.addWidget(st_box, 1)
        left.setMinimumWidth(370)
        left.setMaximumWidth(460)
        right, self.tabs = plots_over_tabs(self.plots, self.results, self.log)
        right.setSizes([540, 260])  # the recorded results get room to read
        split = QSplitter(Qt.Orientation.Horizontal)
        split.addWidget(left)
        split.addWidget(right)
        split.setStretchFactor(1, 1)
        central = QWidget()
        outer = QVBoxLayout(central)
        outer.setContentsMargins(4, 4, 4, 4)
        outer.addWidget(self.banner)
        outer.addWidget(split, 1)
        self.setCentralWidget(central)

        export_action = QAction("&Export...", self)
        export_action.triggered.connect(lambda: self.export_dialog())
        from .export import add_plot_menus

        add_plot_menus(self.plots, self.export_dialog)
        close_action = QAction("&Close", self)
        close_action.triggered.connect(self.close)
        menu = self.menuBar().addMenu("&File")
        menu.addAction(export_action)
        menu.addAction(close_action)
        self._show()

    def _show(self) -> None:
        rec = self.recorded
        if rec.error:
            self.banner.setText(rec.error)
            self.banner.setStyleSheet(BANNER_STYLES["red"])
            self.identity.setText(str(rec.path))
            self.statusBar().showMessage(rec.error[:200])
            return
        a = rec.attrs
        if rec.incomplete:
            self.banner.setText(f"Incomplete raw file: {rec.incomplete}. What was recorded up to then is shown.")
            self.banner.setStyleSheet(BANNER_STYLES["amber"])
        else:
            self.banner.setText(f"Replay of a recorded run ({a.get('outcome', '?')}): nothing here drives the station.")
            self.banner.setStyleSheet(BANNER_STYLES["green"])
        duts = a.get("duts") or []
        lines = [f"run {a.get('run_id', rec.path.stem)}", f"procedure {a.get('procedure', '?')}",
                 f"station {a.get('station_id', '?')}" + (" (simulated)" if a.get("simulated") else ""),
                 f"started {a.get('started_at', '?')}", f"outcome {a.get('outcome', 'none recorded')}",
                 f"seed {a.get('seed', '-')}", f"DUTs {', '.join(map(str, duts)) if duts else '-'}",
                 f"raw file {rec.path}"]
        self.identity.setText("\n".join(lines))
        self.params.setRowCount(len(rec.params))
        for r, cells in enumerate(rec.params):
            for c, text in enumerate(cells):
                item = QTableWidgetItem(text)
                item.setFlags(item.flags() & ~Qt.ItemFlag.ItemIsEditable)
                self.params.setItem(r, c, item)
        station = a.get("station")
        _fill_tree(self.station, station if isinstance(station, dict) else {"id": a.get("station_id", "?")})
        self.station.expandToDepth(0)
        self.station.resizeColumnToContents(0)
        self.params.resizeRowsToContents()
        from procedures import measurement_periods, no_truth_reasons

        proc = str(a.get("procedure", "")) or None
        self.results.set_truth(_recorded_truths(a), measurement_periods(proc), no_truth_reasons(proc))
        self._apply(rec.events)
        self.results.set_report(str(rec.path))
        self.statusBar().showMessage(f"replay of {rec.path}")

    def _apply(self, events: list[ev.Event]) -> None:
        """Feed the recorded events to this window's own widgets (the plots join the blocks)."""
        blocks: dict[tuple[str, tuple[str, ...]], list[np.ndarray]] = {}
        for e in events:
            if isinstance(e, ev.SampleBlock):
                blocks.setdefault((e.stream, tuple(e.columns)), []).append(np.asarray(e.data))
            elif isinstance(e, ev.RunStarted):
                from .plots import layout_for

                self.plots.set_layout(layout_for(e.procedure))  # the plots the procedure's run showed live
                self.plots.clear()
                self.plots.set_bryan_factor(e.params.get("bryan_factor"))  # the K the run used (recorded)
                self.plots.set_origin(e.t_sim_s)  # time since the run started (bench.gui.replay.run_start_s)
            elif isinstance(e, ev.StreamDeclared):
                self.plots.declare(e.schema)
            elif isinstance(e, ev.FitUpdate):
                self.plots.set_fit(e.name, e.curves)
            elif isinstance(e, ev.Measurement):
                self.results.add(e.name, e.value, e.unit, e.low, e.high, e.outcome, e.dut, ci95=e.ci95)
            elif isinstance(e, ev.Log):
                self.log.add(e.t_sim_s, e.level, e.message)
            elif isinstance(e, ev.RunFinished):
                for (stream, cols), arrays in blocks.items():
                    self.plots.add_samples(stream, cols, np.concatenate(arrays))
                blocks = {}
                self.results.set_outcome(e.outcome, e.safe_state, str(self.recorded.attrs.get("end_reason", "")))
        for (stream, cols), arrays in blocks.items():
            self.plots.add_samples(stream, cols, np.concatenate(arrays))
        self.plots.refresh(force=True)

    # --- actions ------------------------------------------------------------------------------
    def export_dialog(self, title: str | None = None) -> Any:
        from .export import ExportDialog

        dialog = ExportDialog(self.plots, self.raw_file, self, title)
        dialog.open()
        return dialog

    def open_report(self) -> None:
        """Render the run's report if needed and open it in the browser (or say why not)."""
        from .open_report import ensure_report, open_in_browser

        if self.raw_file is None:
            return
        try:
            path = ensure_report(self.raw_file)
        except (OSError, RuntimeError, KeyError, ValueError) as exc:
            self.log.add(0.0, "ERROR", f"report failed: {exc}")
            self.statusBar().showMessage(f"report failed: {exc}"[:200])
            return
        self.report_dialog = open_in_browser(path, self)

    def closeEvent(self, event) -> None:  # noqa: N802 - Qt's name
        self.plots.shutdown()
        super().closeEvent(event)


def _recorded_truths(attrs: dict[str, Any]) -> dict[str, float]:
    """The true value of each declared measurement from the truth the file recorded (a simulated
    run; a real one has none), by the procedure's declarations, as the live window shows it."""
    truth = attrs.get("truth")
    if not isinstance(truth, dict):
        return {}
    try:
        from procedures import find_procedure

        return find_procedure(str(attrs.get("procedure", ""))).truth_for(truth)
    except Exception:  # noqa: BLE001 - an unknown or renamed procedure: no truth column
        return {}
