"""Take a plot's data away: the full recorded stream behind it (read from the run's raw file, not
the decimated curve that is drawn) as CSV or HDF5 with column names and units, and the figure
itself as PNG or SVG (pyqtgraph's image exporter; Qt's SVG painter).  `ExportDialog` is File > Export... of a window:
it offers the plots the run has data for, and writes raw data off the GUI thread with a progress
bar, then says where and how large the file is."""

from __future__ import annotations

import json
import re
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import h5py
import numpy as np
from PySide6.QtCore import QObject, Signal
from PySide6.QtWidgets import (
    QComboBox,
    QDialog,
    QDialogButtonBox,
    QFileDialog,
    QFormLayout,
    QLabel,
    QProgressBar,
    QWidget,
)

CSV_CHUNK_ROWS = 20_000  # rows written between two progress reports

FORMATS = {"CSV (raw data)": "csv", "HDF5 (raw data)": "h5", "PNG (figure)": "png", "SVG (figure)": "svg"}


#: each plot of a LivePlots by a plain name (its title is a coloured legend that may change)
PLOTS = (("cx sx cy sy", "p_q", "fpga"), ("E", "p_e", "fpga"), ("wave angle", "p_theta", "fpga"),
         ("table rate", "p_rate", "table"), ("sweep amplitude", "p_amp", "sweep"),
         ("sweep phase", "p_phase", "sweep"), ("rate output", "p_cvg", "fpga"),
         ("Allan deviation", "p_allan", "cvg_allan_curve"), ("temperature", "p_temp", "chamber"))
E_FIT_KEYS = ("energy_fit", "E_fit")  # a stored fit's model E(t) (fits/<name>/<key>, over its t_s)


def plot_sources(plots: Any) -> dict[str, tuple[Any, str]]:
    """Each plot of a LivePlots by its plain name: (its PlotItem, the recorded stream behind it)."""
    return {name: (getattr(plots, attr), stream) for name, attr, stream in PLOTS}


def offered_plots(plots: Any, raw_file: str | Path | None) -> list[str]:
    """The plots an export can take: those the window shows for this run (a sweep plot only on a
    run with a sweep) and, with a raw file, whose stream the file holds."""
    streams = None
    if raw_file is not None:
        try:
            with h5py.File(raw_file, "r") as f:
                streams = set(f["streams"]) if "streams" in f else None
        except OSError:
            streams = None
    out = []
    for name, (plot_item, stream) in plot_sources(plots).items():
        view = plot_item.getViewWidget()
        if view is not None and view.isHidden():
            continue
        if streams is not None and stream not in streams:
            continue
        out.append(name)
    return out


def _with_energy(raw_file: str | Path, rows: np.ndarray, cols: list[str], units: list[str]
                 ) -> tuple[np.ndarray, list[str], list[str]]:
    """The FPGA rows with E = cx^2 + sx^2 + cy^2 + sy^2 and the run's stored fit of E at each row's
    time (log-interpolated between the fit's points; NaN outside its span or without a fit)."""
    q = rows[:, [cols.index(c) for c in ("cx", "sx", "cy", "sy")]]
    e = np.sum(q * q, axis=1)
    t = rows[:, cols.index("t_s")]
    fit = np.full(len(rows), np.nan)
    with h5py.File(raw_file, "r") as f:
        for group in (f["fits"].values() if "fits" in f else ()):
            key = next((k for k in E_FIT_KEYS if k in group), None)
            if key is None or "t_s" not in group:
                continue
            tf, ef = np.asarray(group["t_s"][()], float), np.asarray(group[key][()], float)
            ok = np.isfinite(tf) & np.isfinite(ef) & (ef > 0)
            tf, ef = tf[ok], ef[ok]
            if len(tf) >= 2:
                order = np.argsort(tf)
                tf, ef = tf[order], ef[order]
                inside = (t >= tf[0]) & (t <= tf[-1])
                fit[inside] = np.exp(np.interp(t[inside], tf, np.log(ef)))
    unit = units[cols.index("cx")]
    e_unit = "1" if unit in ("", "1") else f"{unit}^2"
    return np.column_stack((rows, e, fit)), [*cols, "E", "E_fit"], [*units, e_unit, e_unit]


def plot_data(raw_file: str | Path, title: str) -> tuple[np.ndarray, list[str], list[str], dict[str, Any], str]:
    """(rows, columns, units, run attributes, stream) a plot's export holds: its stream as
    recorded; for "E", with E and its fit beside the slow variables."""
    stream = dict((n, s) for n, _a, s in PLOTS)[title]
    rows, cols, units, run = read_stream(raw_file, stream)
    if title == "E" and all(c in cols for c in ("t_s", "cx", "sx", "cy", "sy")):
        rows, cols, units = _with_energy(raw_file, rows, cols, units)
    return rows, cols, units, run, stream


def read_stream(raw_file: str | Path, stream: str) -> tuple[np.ndarray, list[str], list[str], dict[str, Any]]:
    """(rows, column names, units, run attributes) of one stream of a raw file, exactly as recorded."""
    from bench.recorder import open_run

    with open_run(raw_file) as data:
        if stream not in data:
            have = ", ".join(data.streams()) or "none"
            raise KeyError(f"{Path(raw_file).name} has no stream {stream!r} (it has: {have})")
        cols = data.columns(stream)
        units = data.units(stream)
        rows = data.array(stream)
        run = {k: data.attrs[k] for k in ("run_id", "procedure", "station_id") if k in data.attrs}
    return rows, cols, [units.get(c, "") for c in cols], run


def export_csv(raw_file: str | Path, stream: str, out: str | Path, *, title: str | None = None,
               progress: Callable[[float], None] | None = None) -> int:
    """The stream's recorded rows as CSV (a plot's, by `title`: "E" adds E and its fit): `#` lines
    say where they come from, then one header line `name [unit],...`, then the rows to full
    precision (a float64 reads back bit for bit); `progress(fraction)` between chunks.  Rows written."""
    if title is not None:
        rows, cols, units, run, stream = plot_data(raw_file, title)
    else:
        rows, cols, units, run = read_stream(raw_file, stream)
    header = ",".join(f"{c} [{u}]" if u else c for c, u in zip(cols, units, strict=True))
    with open(out, "w", encoding="utf-8", newline="\n") as fh:
        fh.write(f"# gyrobench raw data: stream {stream} of run {run.get('run_id', '?')} "
                 f"({run.get('procedure', '?')} on {run.get('station_id', '?')}), {len(rows)} rows\n")
        fh.write(f"# from {Path(raw_file).resolve()}\n")
        fh.write(header + "\n")
        for i in range(0, len(rows), CSV_CHUNK_ROWS):
            np.savetxt(fh, rows[i:i + CSV_CHUNK_ROWS], delimiter=",", fmt="%.17g")
            if progress is not None:
                progress(min(1.0, (i + CSV_CHUNK_ROWS) / len(rows)))
    return len(rows)


def export_hdf5(raw_file: str | Path, stream: str, out: str | Path, *, title: str | None = None) -> int:
    """The stream's recorded rows as `/<stream>` in a new HDF5 file (a plot's, by `title`: "E"
    adds E and its fit), with `columns` and `units` attributes (as the raw file has them) and the
    run's identity on the root.  Rows written."""
    if title is not None:
        rows, cols, units, run, stream = plot_data(raw_file, title)
    else:
        rows, cols, units, run = read_stream(raw_file, stream)
    with h5py.File(out, "w") as f:
        ds = f.create_dataset(stream, data=rows)
        ds.attrs["columns"] = json.dumps(cols)
        ds.attrs["units"] = np.array(units, dtype=h5py.string_dtype())
        for k, v in run.items():
            f.attrs[k] = str(v)
        f.attrs["source_file"] = str(Path(raw_file).resolve())
    return len(rows)


def _export_svg(plot_item: Any, out: Path) -> None:
    """The plot's region of its scene through Qt's own SVG painter (pyqtgraph's SVGExporter fails
    on this Qt's path output: "not enough values to unpack" while it rewrites polyline points)."""
    from PySide6.QtCore import QRectF
    from PySide6.QtGui import QPainter
    from PySide6.QtSvg import QSvgGenerator

    rect = plot_item.sceneBoundingRect()
    gen = QSvgGenerator()
    gen.setFileName(str(out))
    gen.setSize(rect.size().toSize())
    gen.setViewBox(QRectF(0, 0, rect.width(), rect.height()))
    gen.setTitle(re.sub(r"<[^>]+>", "", plot_item.titleLabel.text or "") or "gyrobench plot")
    painter = QPainter(gen)
    try:
        plot_item.scene().render(painter, QRectF(0, 0, rect.width(), rect.height()), rect)
    finally:
        painter.end()


def export_figure(plot_item: Any, out: str | Path) -> Path:
    """One plot as PNG (pyqtgraph's ImageExporter, at 2x its size on screen) or SVG, by the suffix."""
    import pyqtgraph.exporters as pex

    out = Path(out)
    if out.suffix.lower() == ".svg":
        _export_svg(plot_item, out)
    else:
        exporter = pex.ImageExporter(plot_item)
        exporter.parameters()["width"] = max(800, int(plot_item.sceneBoundingRect().width() * 2))
        exporter.export(str(out))
    if not out.exists():
        raise OSError(f"the exporter wrote nothing to {out}")
    return out


def file_size_text(path: str | Path) -> str:
    """A file's size as a person reads it: '812 B', '4.2 kB', '59.3 MB'."""
    n = Path(path).stat().st_size
    for unit, scale in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= scale:
            return f"{n / scale:.1f} {unit}"
    return f"{n} B"


def export_plot(plots: Any, title: str, raw_file: str | Path | None, out: str | Path,
                progress: Callable[[float], None] | None = None) -> str:
    """Export the plot named `title` to `out` (the format from its suffix: .csv, .h5/.hdf5, .png,
    .svg); a one-line note of what was written, with the file's size.  The raw data needs the
    run's raw file (it may be called off the GUI thread; a figure may not)."""
    plot_item, stream = plot_sources(plots)[title]
    suffix = Path(out).suffix.lower()
    if suffix in (".png", ".svg"):
        path = export_figure(plot_item, out)
        return f"figure {title!r} written to {path} ({file_size_text(path)})"
    if raw_file is None:
        raise ValueError("no recorded run is shown: the raw data comes from a run's raw file")
    if suffix == ".csv":
        n = export_csv(raw_file, stream, out, title=title, progress=progress)
    elif suffix in (".h5", ".hdf5"):
        n = export_hdf5(raw_file, stream, out, title=title)
    else:
        raise ValueError(f"cannot export to {suffix or 'a file without a suffix'}: use .csv, .h5, .png or .svg")
    extra = " with E and its fit" if title == "E" else ""
    return f"{n} rows of stream {stream!r} ({title}{extra}) written to {out} ({file_size_text(out)})"


class _ExportSignals(QObject):
    """A background export's news, delivered in the GUI thread (queued across threads)."""

    progress = Signal(float)
    finished = Signal(str, bool)  # note, ok


def add_plot_menus(plots: Any, open_dialog: Any) -> None:
    """Each plot's right-click menu gets "Export data or figure...", which opens the export dialog
    on that plot (pyqtgraph's own "Export..." there writes the decimated curve, not the record)."""
    for title, (plot_item, _stream) in plot_sources(plots).items():
        menu = plot_item.getViewBox().menu
        action = menu.addAction("Export recorded data or figure...")
        action.triggered.connect(lambda _checked=False, t=title: open_dialog(t))


class ExportDialog(QDialog):
    """Pick a plot and a format, then a file: File > Export... of the live window and the replay.
    Raw data is written by a worker thread (the window keeps drawing) with a progress bar; the
    note with the file's path and size goes to the parent window's status bar."""

    def __init__(self, plots: Any, raw_file: str | None, parent: QWidget | None = None,
                 title: str | None = None) -> None:
        super().__init__(parent)
        self.setWindowTitle("Export")
        self.plots = plots
        self.raw_file = raw_file
        form = QFormLayout(self)
        self.plot = QComboBox()
        self.plot.addItems(offered_plots(plots, raw_file))  # never a plot this run has no data for
        if title:
            self.plot.setCurrentText(title)
        self.format = QComboBox()
        self.format.addItems(list(FORMATS))
        form.addRow("plot", self.plot)
        form.addRow("format", self.format)
        src = f"raw data from {raw_file}" if raw_file else "no recorded run shown: figures only"
        note = QLabel(f"CSV and HDF5 hold every recorded sample of the plot's stream ({src}; E with its "
                      "fit); PNG and SVG hold the figure as drawn.")
        note.setWordWrap(True)
        form.addRow(note)
        self.progress = QProgressBar()
        self.progress.setRange(0, 1000)
        self.progress.setVisible(False)
        form.addRow(self.progress)
        self.buttons = QDialogButtonBox(QDialogButtonBox.StandardButton.Save | QDialogButtonBox.StandardButton.Cancel)
        self.buttons.accepted.connect(self._save)
        self.buttons.rejected.connect(self.reject)
        form.addRow(self.buttons)
        self.result_note = ""
        self.worker: threading.Thread | None = None
        self.signals = _ExportSignals(self)
        self.signals.progress.connect(lambda f: self.progress.setValue(int(round(1000 * f))))
        self.signals.finished.connect(self._finished)

    def _save(self) -> None:
        ext = FORMATS[self.format.currentText()]
        stem = Path(self.raw_file).stem if self.raw_file else "plot"
        name = self.plot.currentText().split(" ")[0].strip(",")
        path, _ = QFileDialog.getSaveFileName(self, "Export", f"{stem}_{name}.{ext}", f"*.{ext}")
        if not path:
            return
        self.export_to(path)

    def export_to(self, path: str) -> str:
        """Export the chosen plot to `path` (the dialog's Save, without the file dialog).  A figure
        is drawn here (the note at once); raw data is written by a worker thread: the note says
        it started, `result_note` holds the outcome once `worker` is done."""
        title = self.plot.currentText()
        if Path(path).suffix.lower() in (".png", ".svg") or self.raw_file is None:
            try:
                note = export_plot(self.plots, title, self.raw_file, path)
            except (OSError, KeyError, ValueError, RuntimeError) as exc:
                self._finished(f"export failed: {exc}", False)
                return self.result_note
            self._finished(note, True)
            return self.result_note
        self.result_note = ""
        self.progress.setValue(0)
        self.progress.setVisible(True)
        self.buttons.button(QDialogButtonBox.StandardButton.Save).setEnabled(False)
        self.plot.setEnabled(False)
        self.format.setEnabled(False)
        started = f"exporting {title!r} to {path}..."
        self._status(started)

        signals = self.signals

        def report(fraction: float) -> None:
            try:
                signals.progress.emit(fraction)
            except RuntimeError:  # the dialog was closed meanwhile: the file is still written
                pass

        def work() -> None:
            try:
                note = export_plot(self.plots, title, self.raw_file, path, progress=report)
                ok = True
            except (OSError, KeyError, ValueError, RuntimeError) as exc:
                note, ok = f"export failed: {exc}", False
            try:
                signals.finished.emit(note, ok)
            except RuntimeError:
                pass

        self.worker = threading.Thread(target=work, name="gyrobench-export", daemon=True)
        self.worker.start()
        return started

    def _finished(self, note: str, ok: bool) -> None:
        """GUI thread: the export's note to the status bar (and a warning box when it failed)."""
        from PySide6.QtWidgets import QMessageBox

        self.result_note = note
        self.progress.setVisible(False)
        self.buttons.button(QDialogButtonBox.StandardButton.Save).setEnabled(True)
        self.plot.setEnabled(True)
        self.format.setEnabled(True)
        self._status(note)
        if not ok:
            QMessageBox.warning(self, "gyrobench", note)
            return
        self.accept()

    def _status(self, text: str) -> None:
        bar = getattr(self.parent(), "statusBar", None)
        if callable(bar):
            bar().showMessage(text, 0)

    def wait(self, timeout_s: float = 60.0) -> str:
        """Join the export's worker and deliver its note (tests; a closing window)."""
        from PySide6.QtWidgets import QApplication

        if self.worker is not None:
            self.worker.join(timeout_s)
        QApplication.processEvents()
        return self.result_note
