"""Take a plot's data away: the full recorded stream behind it (read from the run's raw file, not
the decimated curve that is drawn) as CSV or HDF5 with column names and units, and the figure
itself as PNG or SVG (pyqtgraph's image exporter; Qt's SVG painter).  `ExportDialog` is File > Export... of a window."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import h5py
import numpy as np
from PySide6.QtWidgets import (
    QComboBox,
    QDialog,
    QDialogButtonBox,
    QFileDialog,
    QFormLayout,
    QLabel,
    QWidget,
)

FORMATS = {"CSV (raw data)": "csv", "HDF5 (raw data)": "h5", "PNG (figure)": "png", "SVG (figure)": "svg"}


#: each plot of a LivePlots by a plain name (its title is a coloured legend that may change)
PLOTS = (("cx sx cy sy", "p_q", "fpga"), ("E", "p_e", "fpga"), ("wave angle", "p_theta", "fpga"),
         ("table rate", "p_rate", "table"), ("sweep amplitude", "p_amp", "sweep"),
         ("sweep phase", "p_phase", "sweep"))


def plot_sources(plots: Any) -> dict[str, tuple[Any, str]]:
    """Each plot of a LivePlots by its plain name: (its PlotItem, the recorded stream behind it)."""
    return {name: (getattr(plots, attr), stream) for name, attr, stream in PLOTS}


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


def export_csv(raw_file: str | Path, stream: str, out: str | Path) -> int:
    """The stream's recorded rows as CSV: `#` lines say where they come from, then one header line
    `name [unit],...`, then the rows to full precision (a float64 reads back bit for bit).  Rows written."""
    rows, cols, units, run = read_stream(raw_file, stream)
    header = ",".join(f"{c} [{u}]" if u else c for c, u in zip(cols, units, strict=True))
    with open(out, "w", encoding="utf-8", newline="\n") as fh:
        fh.write(f"# gyrobench raw data: stream {stream} of run {run.get('run_id', '?')} "
                 f"({run.get('procedure', '?')} on {run.get('station_id', '?')}), {len(rows)} rows\n")
        fh.write(f"# from {Path(raw_file).resolve()}\n")
        fh.write(header + "\n")
        np.savetxt(fh, rows, delimiter=",", fmt="%.17g")
    return len(rows)


def export_hdf5(raw_file: str | Path, stream: str, out: str | Path) -> int:
    """The stream's recorded rows as `/<stream>` in a new HDF5 file, with `columns` and `units`
    attributes (as the raw file has them) and the run's identity on the root.  Rows written."""
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


def export_plot(plots: Any, title: str, raw_file: str | Path | None, out: str | Path) -> str:
    """Export the plot named `title` to `out` (the format from its suffix: .csv, .h5/.hdf5, .png,
    .svg); a one-line note of what was written.  The raw data needs the run's raw file."""
    plot_item, stream = plot_sources(plots)[title]
    suffix = Path(out).suffix.lower()
    if suffix in (".png", ".svg"):
        return f"figure {title!r} written to {export_figure(plot_item, out)}"
    if raw_file is None:
        raise ValueError("no recorded run is shown: the raw data comes from a run's raw file")
    if suffix == ".csv":
        n = export_csv(raw_file, stream, out)
    elif suffix in (".h5", ".hdf5"):
        n = export_hdf5(raw_file, stream, out)
    else:
        raise ValueError(f"cannot export to {suffix or 'a file without a suffix'}: use .csv, .h5, .png or .svg")
    return f"{n} rows of stream {stream!r} ({title}) written to {out}"


def add_plot_menus(plots: Any, open_dialog: Any) -> None:
    """Each plot's right-click menu gets "Export data or figure...", which opens the export dialog
    on that plot (pyqtgraph's own "Export..." there writes the decimated curve, not the record)."""
    for title, (plot_item, _stream) in plot_sources(plots).items():
        menu = plot_item.getViewBox().menu
        action = menu.addAction("Export recorded data or figure...")
        action.triggered.connect(lambda _checked=False, t=title: open_dialog(t))


class ExportDialog(QDialog):
    """Pick a plot and a format, then a file: File > Export... of the live window and the replay."""

    def __init__(self, plots: Any, raw_file: str | None, parent: QWidget | None = None,
                 title: str | None = None) -> None:
        super().__init__(parent)
        self.setWindowTitle("Export")
        self.plots = plots
        self.raw_file = raw_file
        form = QFormLayout(self)
        self.plot = QComboBox()
        self.plot.addItems(list(plot_sources(plots)))
        if title:
            self.plot.setCurrentText(title)
        self.format = QComboBox()
        self.format.addItems(list(FORMATS))
        form.addRow("plot", self.plot)
        form.addRow("format", self.format)
        src = f"raw data from {raw_file}" if raw_file else "no recorded run shown: figures only"
        note = QLabel(f"CSV and HDF5 hold every recorded sample of the plot's stream ({src}); "
                      "PNG and SVG hold the figure as drawn.")
        note.setWordWrap(True)
        form.addRow(note)
        buttons = QDialogButtonBox(QDialogButtonBox.StandardButton.Save | QDialogButtonBox.StandardButton.Cancel)
        buttons.accepted.connect(self._save)
        buttons.rejected.connect(self.reject)
        form.addRow(buttons)
        self.result_note = ""

    def _save(self) -> None:
        ext = FORMATS[self.format.currentText()]
        stem = Path(self.raw_file).stem if self.raw_file else "plot"
        name = self.plot.currentText().split(" ")[0].strip(",")
        path, _ = QFileDialog.getSaveFileName(self, "Export", f"{stem}_{name}.{ext}", f"*.{ext}")
        if not path:
            return
        self.export_to(path)

    def export_to(self, path: str) -> str:
        """Export the chosen plot to `path` (the dialog's Save, without the file dialog); the note."""
        from PySide6.QtWidgets import QMessageBox

        try:
            self.result_note = export_plot(self.plots, self.plot.currentText(), self.raw_file, path)
        except (OSError, KeyError, ValueError, RuntimeError) as exc:
            self.result_note = f"export failed: {exc}"
            QMessageBox.warning(self, "gyrobench", self.result_note)
            return self.result_note
        self.accept()
        return self.result_note
