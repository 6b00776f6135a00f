"""Shared figure helpers: matplotlib figures (Agg, no pyplot state) with axes that name their
quantity and unit, min/max envelopes for long records, fits over data with a residual panel,
equal-aspect polar plots, and the figure's SVG for the report."""

from __future__ import annotations

import io
import re
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import matplotlib


def _short_property_docs() -> None:
    """matplotlib writes every Artist class's set() docstring, a table of all its properties, as
    the class is made: ~0.1 s, a fifth of its import and of a report's serial start (issue 36,
    benchmarks/report_speed.py).  Nothing here reads those docstrings, so before matplotlib's
    artists are first made the table is one line; once they are (a window's pyplot), nothing changes."""
    if "matplotlib.lines" in sys.modules:
        return
    import matplotlib.artist

    if callable(getattr(matplotlib.artist, "kwdoc", None)):
        matplotlib.artist.kwdoc = lambda _artist: "Properties: see matplotlib's documentation."


_short_property_docs()
if "matplotlib.pyplot" not in sys.modules:  # off screen; figures here never touch pyplot's state
    matplotlib.use("Agg")
import numpy as np  # noqa: E402
from matplotlib.axes import Axes  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from bench.numbers import pretty_unit  # noqa: E402

#: points of a record drawn as a line; longer records are drawn as a min/max envelope of this many bins
ENVELOPE_BINS = 1200
#: resolution of the figures in the PDF: WeasyPrint draws an inline SVG of ~2,500 paths in ~3 s,
#: the same figure as a 200 dpi PNG in ~0.1 s (benchmarks/report_speed.py)
PRINT_DPI = 200
WIDTH_IN = 7.6
_RC = {
    "font.size": 8.5,
    "axes.titlesize": 9.5,
    "axes.labelsize": 8.5,
    "legend.fontsize": 7.5,
    "axes.grid": True,
    "grid.alpha": 0.3,
    "lines.linewidth": 1.0,
    "svg.fonttype": "none",  # text stays text: small files, selectable, the page's font
    "svg.hashsalt": None,
}
matplotlib.rcParams.update(_RC)

#: an axis whose column the run did not declare a unit for shows this (a defect the tests catch)
NO_UNIT = "no unit declared"


def unit_text(unit: str | None) -> str:
    """A declared unit as an axis writes it ("1": a quantity of dimension one; deg/s^2 as deg/s²)."""
    return pretty_unit(unit) if unit else NO_UNIT


def declared(data: Any, source: str, column: str) -> tuple[str, str]:
    """(quantity, unit) of a stream's column or a fit's curve as the run declared it (the raw
    file's declaration, bench.streams); the unit is "" where nothing was declared."""
    try:
        return data.declared(source).get(column, (column, ""))
    except KeyError:
        return column, ""


def axis_label(data: Any, source: str, column: str, *, quantity: str | None = None, short: bool = False) -> str:
    """Axis label 'quantity (unit)' of a declared column (quantity: words for a derived axis in
    the column's unit); short: 'column' over '(unit)', for stacked narrow panels."""
    q, unit = declared(data, source, column)
    if short:
        return f"{column}\n({unit_text(unit)})"
    return f"{quantity or q} ({unit_text(unit)})"


def log_label(name: str, unit: str) -> str:
    """Axis label of the natural log of a declared quantity: 'ln E (1)', or 'ln(E / unit) (1)'."""
    if not unit:
        return f"ln {name} ({NO_UNIT})"
    return f"ln {name} (1)" if unit == "1" else f"ln({name} / {unit}) (1)"


def measured_label(quantity: str, m: dict[str, Any] | None) -> str:
    """Axis label of a quantity in the unit of a recorded measurement (as its procedure declared it)."""
    unit = None if m is None else (m.get("unit") or "1")
    return f"{quantity} ({unit_text(unit)})"


@dataclass
class ReportFigure:
    """One figure of a report: a file-name key, a title, the matplotlib figure and a note."""

    key: str
    title: str
    figure: Figure
    note: str = ""
    #: numbers the figure supports, shown beneath it: (header, rows of text)
    table: tuple[list[str], list[list[str]]] | None = None

    def svg(self) -> str:
        """The figure as an inline <svg> element (no XML prologue)."""
        buf = io.StringIO()
        self.figure.savefig(buf, format="svg", metadata={"Date": None})
        self._keep_layout()
        text = buf.getvalue()
        return text[text.index("<svg"):]

    def png(self, dpi: int = PRINT_DPI) -> bytes:
        """The figure as PNG (Agg) at dpi: the PDF's figure, drawn in the layout the SVG had.  RGB
        on its opaque background, quickly compressed: WeasyPrint decodes and compresses it again
        into the PDF, and an alpha channel it splits into a second image (benchmarks/report_speed.py)."""
        from PIL import Image

        buf = io.BytesIO()
        self.figure.savefig(buf, format="rgba", dpi=dpi)
        self._keep_layout()
        width, height = (int(s * dpi) for s in self.figure.get_size_inches())
        rgba = np.frombuffer(buf.getbuffer(), dtype=np.uint8)
        if self.figure.get_facecolor()[3] < 1.0 or rgba.size != width * height * 4:  # keep what Agg gave
            out = io.BytesIO()
            self.figure.savefig(out, format="png", dpi=dpi)
            return out.getvalue()
        out = io.BytesIO()
        Image.fromarray(rgba.reshape(height, width, 4)[:, :, :3]).save(out, format="PNG", compress_level=1,
                                                                       dpi=(dpi, dpi))
        return out.getvalue()

    def _keep_layout(self) -> None:
        """Freeze the constrained layout just computed: a second format (SVG then PNG) draws the
        figure once instead of laying it out again (half of a figure's drawing time)."""
        self.figure.set_layout_engine("none")

    def save(self, directory: str | Path, fmt: str = "svg") -> Path:
        path = Path(directory) / f"{re.sub(r'[^A-Za-z0-9_.-]+', '_', self.key)}.{fmt}"
        self.figure.savefig(path, format=fmt, metadata={"Date": None} if fmt in ("svg", "pdf") else None)
        self._keep_layout()
        return path


def new_figure(nrows: int = 1, ncols: int = 1, *, height_in: float = 3.0, width_in: float = WIDTH_IN,
               layout: str = "constrained", **kwargs: Any) -> tuple[Figure, Any]:
    """A figure laid out so labels are never clipped, and its axes array.  layout "measured": one
    grid of axes with titles and a legend above them, laid out in one pass (bench.figure_layout;
    about a third less drawing time); "constrained": matplotlib's layout, for anything else."""
    from matplotlib.ticker import MaxNLocator

    if layout == "measured":
        from bench.figure_layout import MeasuredLayout

        fig = Figure(figsize=(width_in, height_in), layout=MeasuredLayout())
    else:
        fig = Figure(figsize=(width_in, height_in), layout=layout)
    axes = fig.subplots(nrows, ncols, squeeze=False, **kwargs)
    if ncols > 1:  # narrow panels: fewer x ticks, so their labels do not run into each other
        for ax in axes.flat:
            ax.xaxis.set_major_locator(MaxNLocator(nbins=4 if ncols > 2 else 5))
    return fig, axes


def envelope(x: np.ndarray, y: np.ndarray, bins: int = ENVELOPE_BINS) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(x, min, max) over `bins` equal runs of samples: what a long record looks like on paper,
    every sample represented (no sample dropped, so no aliasing); short records come back as
    (x, y, y)."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    n = len(y)
    if n <= 2 * bins:
        return x, y, y
    per = n // bins
    m = per * bins
    yb = y[:m].reshape(bins, per)
    lo, hi = np.nanmin(yb, axis=1), np.nanmax(yb, axis=1)
    xb = x[:m].reshape(bins, per).mean(axis=1)
    if m < n:  # the tail that does not fill a bin
        xb = np.append(xb, x[m:].mean())
        lo = np.append(lo, np.nanmin(y[m:]))
        hi = np.append(hi, np.nanmax(y[m:]))
    return xb, lo, hi


def plot_record(ax: Axes, x: np.ndarray, y: np.ndarray, *, color: str | None = None, label: str | None = None,
                **kwargs: Any) -> None:
    """A record as a line, or as its min/max envelope when it is long."""
    xe, lo, hi = envelope(x, y)
    if lo is hi:
        if len(xe) < 100:  # a few readings: each one marked, so the line is not read as a record
            kwargs = {"marker": "o", "markersize": 2.5, **kwargs}
        ax.plot(xe, lo, color=color, label=label, **kwargs)
        return
    poly = ax.fill_between(xe, lo, hi, color=color, linewidth=0.6, label=label, alpha=0.8)
    if color is None:
        poly.set_edgecolor(poly.get_facecolor())


def fit_with_residuals(x: np.ndarray, y: np.ndarray, y_fit: np.ndarray, *, xlabel: str, ylabel: str,
                       data_label: str = "measured", fit_label: str = "fit",
                       residual: np.ndarray | None = None, residual_label: str | None = None,
                       height_in: float = 3.6, layout: str = "constrained") -> Figure:
    """Data with the fitted curve over them and the residual (data - fit) in a panel beneath."""
    fig, ax = new_figure(2, 1, height_in=height_in, sharex=True, gridspec_kw={"height_ratios": [3, 1.3]},
                         layout=layout)
    top, bottom = ax[0, 0], ax[1, 0]
    if len(x) <= 2 * ENVELOPE_BINS:  # points under the curve, so the curve does not hide them
        top.plot(x, y, ".", color="C0", markersize=2.5, label=data_label)
    else:
        plot_record(top, x, y, color="C0", label=data_label)
    xf, _, yf = envelope(x, y_fit)
    top.plot(xf, yf, "--", color="C3", label=fit_label, linewidth=1.0)
    top.set_ylabel(ylabel)
    top.legend(loc="best")
    r = np.asarray(y, dtype=float) - np.asarray(y_fit, dtype=float) if residual is None else residual
    plot_record(bottom, x, r, color="C0")
    bottom.axhline(0.0, color="C3", linewidth=0.8)
    bottom.set_ylabel(residual_label or "residual")
    bottom.set_xlabel(xlabel)
    return fig


def equal_aspect(ax: Axes) -> None:
    """1:1 axes for a polar (phase-plane) plot: circles stay circles."""
    ax.set_aspect("equal", adjustable="datalim")
    ax.axhline(0.0, color="0.6", linewidth=0.6)
    ax.axvline(0.0, color="0.6", linewidth=0.6)


def measurement(data: Any, name: str) -> dict[str, Any] | None:
    """The last recorded measurement of that name (None when the run did not report it)."""
    found = None
    for m in data.measurements():
        if m.get("name") == name:
            found = m
    return found


def table_figure(data: Any, layout: str = "constrained") -> list[ReportFigure]:
    """The rate table's rate and angle on their own axes, from the `table` stream."""
    if "table" not in data:
        return []
    tab = data.table("table")
    t = tab.get("t_s")
    if t is None or len(t) < 2:
        return []
    cols = [c for c in ("rate_dps", "angle_deg") if c in tab]
    fig, ax = new_figure(len(cols), 1, height_in=1.6 + 1.2 * len(cols), sharex=True, layout=layout)
    note = f"{len(t)} readings of the table's status."
    for i, c in enumerate(cols):
        if c == "angle_deg" and "rate_dps" in tab:  # reported in [0, 360): unwrapped with the rate readings
            plot_record(ax[i, 0], t, unwrap_angle_deg(t, tab[c], tab["rate_dps"]), color=f"C{i}")
            ax[i, 0].set_ylabel(axis_label(data, "table", c, quantity="table angle, unwrapped"))
            note += (" The table reports its angle in [0, 360); it is unwrapped here with the rate readings (each "
                     "step's whole turns from the rate, the rest from the angle read).")
            continue
        if c == "angle_deg":  # wraps at 360 deg: points, not a line across the wrap
            ax[i, 0].plot(t, tab[c], ".", color=f"C{i}", markersize=1.5 if len(t) > 500 else 3)
        else:
            plot_record(ax[i, 0], t, tab[c], color=f"C{i}")
        ax[i, 0].set_ylabel(axis_label(data, "table", c))
    ax[-1, 0].set_xlabel(axis_label(data, "table", "t_s"))
    return [ReportFigure("table", "Rate table: rate and angle", fig, note)]


def unwrap_angle_deg(t_s: np.ndarray, angle_deg: np.ndarray, rate_dps: np.ndarray) -> np.ndarray:
    """An angle read in [0, 360) made continuous: between two readings the table turned the angle
    difference read plus the whole turns that bring it nearest the rate's trapezoid integral (right
    while the integral errs by under 180 deg a step, which sampling the angle alone cannot give
    above 180 deg a step)."""
    t, a, r = (np.asarray(x, dtype=float) for x in (t_s, angle_deg, rate_dps))
    if len(a) < 2:
        return a
    turned = 0.5 * (r[1:] + r[:-1]) * np.diff(t)
    step = np.diff(a)
    step += 360.0 * np.round((turned - step) / 360.0)
    return np.concatenate([[a[0]], a[0] + np.cumsum(step)])


def stream_figure(data: Any, stream: str, columns: list[str] | None = None, *, title: str | None = None,
                  key: str | None = None, layout: str = "constrained") -> ReportFigure | None:
    """A stream's columns against time, each on its own axis (long records as envelopes)."""
    tab = data.table(stream)
    t = tab.get("t_s")
    cols = [c for c in (columns or tab) if c in tab and c not in ("t_s", "index")]
    if t is None or len(t) < 2 or not cols:
        return None
    fig, ax = new_figure(len(cols), 1, height_in=0.9 + 1.05 * len(cols), sharex=True, layout=layout)
    for i, c in enumerate(cols):
        plot_record(ax[i, 0], t, tab[c], color=f"C{i % 10}")
        ax[i, 0].set_ylabel(axis_label(data, stream, c, short=len(cols) > 2))
    ax[-1, 0].set_xlabel(axis_label(data, stream, "t_s"))
    note = f"{len(t)} rows" + (f", drawn as min/max envelopes of {ENVELOPE_BINS} bins" if len(t) > 2 * ENVELOPE_BINS
                               else "")
    return ReportFigure(key or stream, title or f"Stream {stream}", fig, note + ".")


def generic_figures(data: Any) -> list[ReportFigure]:
    """For a procedure that names no figures: every stream of 10 rows or more, column by column."""
    out = []
    for stream in data.streams():
        tab = data.table(stream)
        if len(tab.get("t_s", ())) >= 10:
            cols = [c for c in tab if c not in ("t_s", "index")][:6]
            fig = stream_figure(data, stream, cols)
            if fig is not None:
                out.append(fig)
    return out
