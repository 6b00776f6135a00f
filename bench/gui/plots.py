"""Live plots of a run: cx, sx, cy, sy; E on a log axis with its fit; wave angle theta; table
rate; and the sweep's amplitude and phase against frequency, filling in point by point; a rate
sensor's (CVG) rate output and its Allan deviation.  Which plots are shown follows the procedure
(`layout_for`): an HRG run the four time plots, a sweep its two sweep plots large, a CVG run its
rate output, the table rate and, once computed, the Allan curve.

Samples go into ring buffers as they arrive (cheap); the curves are redrawn from the buffers by
a QTimer at `refresh_hz`, decimated to `max_points` per curve, never per event.
"""

from __future__ import annotations

import functools
import math
import time
from collections import deque

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import Qt, QTimer
from PySide6.QtWidgets import QGridLayout, QLabel, QWidget

from bench.analysis.slow_model import orbit_elements
from bench.streams import StreamSchema

from .ringbuffer import MinMaxHistory, RingBuffer

FPGA_COLS = ("t_s", "cx", "sx", "cy", "sy", "E", "theta_deg")
_MEAN_CHUNK = 64  # rows of exponential_mean's products (its matrix is _MEAN_CHUNK square)


@functools.cache
def _mean_weights(alpha: float) -> tuple[np.ndarray, np.ndarray]:
    """exponential_mean's (lower-triangular alpha (1 - alpha)^(j - k), (1 - alpha)^(j + 1)) for one chunk."""
    k = np.arange(_MEAN_CHUNK)
    lag = k[:, None] - k[None, :]
    r = 1.0 - alpha
    return np.where(lag >= 0, alpha * r ** np.maximum(lag, 0), 0.0), r ** (k + 1.0)


def exponential_mean(x: np.ndarray, alpha: float, y_prev: complex) -> np.ndarray:
    """y[n] = alpha x[n] + (1 - alpha) y[n-1] from y[-1] = y_prev (a one-pole low-pass), a chunk of
    rows at a time as one small matrix product: scipy.signal.lfilter's numbers to ~1e-15 without
    importing scipy.signal, ~0.7 s of the window's start for this one filter (issue 36)."""
    weights, carry = _mean_weights(float(alpha))
    out = np.empty(len(x), dtype=np.result_type(x, y_prev))
    y = y_prev
    for s in range(0, len(x), _MEAN_CHUNK):
        xs = x[s : s + _MEAN_CHUNK]
        n = len(xs)
        out[s : s + n] = weights[:n, :n] @ xs + carry[:n] * y
        y = out[s + n - 1]
    return out
TABLE_COLS = ("t_s", "rate_dps", "angle_deg")
SWEEP_COLS = ("freq_hz", "amplitude", "phase_deg")
RATE_SPAN_S = 0.1  # the live rate output's differencing span (whole-angle output)
WAVE_COHERENCE_ALPHA = 0.03  # the weight of each row's 4 theta step in the wave test's running mean
WAVE_COHERENCE_MIN = 0.5  # |mean step| above which a wave is there (noise alone: ~0.12)
THETA_TITLE = "wave angle \u03b8"
FTR_TITLE = "rate output (force-to-rebalance)"  # the FPGA's rate_out_dps, in deg/h
NO_WAVE_TITLE = "wave angle \u03b8: no standing wave"  # pickoff noise alone: no angle to draw
TABLE_STREAM = "table"  # the table's own rate stream: the table-rate curve (a procedure's readings are markers)
ALLAN_STREAM, ALLAN_COLS = "cvg_allan_curve", ("tau_s", "adev_dph")  # procedures/cvg_allan.py's curve
#: the chamber's readings the chamber procedures record with each record or segment (t_start_s,
#: t_end_s and some of these: procedures/thermal_soak.py, thermal_ramp.py); drawn at each's middle
TEMP_COLS = ("setpoint_c", "air_c", "part_c")
#: the chamber's own stream (drivers/chamber/watlow_f4_spec.py: a row at every link check): the
#: live air and case curves; the records' readings stand in for them where a chamber has none
CHAMBER_STREAM, CHAMBER_COLS = "chamber", ("air_degc", "part_degc")
TEMP_PENS = {"setpoint_c": ("set point", "#7f7f7f"), "air_c": ("chamber air", "#1f77b4"),
             "part_c": ("case thermocouple", "#d62728")}
#: the plots each layout shows (attribute names of LivePlots' PlotItems)
LAYOUTS = {"hrg": ("p_q", "p_e", "p_theta", "p_rate"), "sweep": ("p_amp", "p_phase"),
           "cvg": ("p_cvg", "p_rate", "p_allan"), "thermal": ("p_temp", "p_cvg", "p_q", "p_e")}
#: LivePlots' PlotItems in the order of its views
PLOT_ATTRS = ("p_q", "p_e", "p_theta", "p_rate", "p_amp", "p_phase", "p_cvg", "p_allan", "p_temp")
RATE_OUTPUT_LAYOUTS = ("cvg", "thermal")  # the layouts with the live rate output (their procedures are CvgOutput)


def layout_for(procedure: str) -> str:
    """The plots a procedure's run shows: 'sweep' (a frequency sweep), 'thermal' (a procedure that
    drives the chamber: its temperatures and the rate output), 'cvg' (a rate sensor's output),
    else 'hrg' (the resonator's slow variables, energy, angle and the table)."""
    if procedure.startswith("mems-sweep") or procedure.endswith("sweep"):
        return "sweep"
    if _uses_chamber(procedure):
        return "thermal"
    if procedure.startswith("cvg-"):
        return "cvg"
    return "hrg"


def _uses_chamber(procedure: str) -> bool:
    """The procedure needs a temperature chamber (its `requires`); an unknown name does not."""
    from procedures import ProcedureNotFound, find_procedure

    try:
        return "chamber" in getattr(find_procedure(procedure), "requires", ())
    except (ProcedureNotFound, OSError, ImportError):
        return False
E_FIT_KEYS = ("E_fit", "energy_fit", "E")  # model E(t) keys of a FitUpdate (not the measured "energy")
PEN_COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728")
FIT_COLOUR = "#d62728"
X_AHEAD = 4.0 / 3.0  # a live time axis extended to this times the data's span (fewer moves, each regenerating ticks)
Y_PAD, Y_FILL_MIN = 0.08, 0.5  # a y range's padding (of the data's span), and the fill below which it shrinks
Y_AHEAD = 0.25  # data leaving a y range: the new one leaves this much of their span ahead on that side
E_LOG_ABOVE, E_LINEAR_BELOW = 10.0, 5.0  # E's max/min ratio at which its axis turns log, and back to linear


def legend_title(*entries: tuple[str, str]) -> str:
    """A plot title that is its legend, above the data: each (name, colour) in its colour."""
    return ", ".join(f'<span style="color:{c}; font-weight:bold">{n}</span>' for n, c in entries)


def squared_unit(unit: str) -> str:
    """The unit of a sum of squares (E = cx^2 + ... ): V -> V\u00b2; dimensionless stays "1"."""
    return "1" if unit in ("", "1") else f"{unit}\u00b2"


def log_ticks(low: float, high: float) -> list[tuple[float, str]]:
    """Labelled ticks of a log axis over [low, high] (positive): 1, 2, 5 of each decade over three
    decades or less, the decades alone over more; as (log10 value, label).  pyqtgraph's own labels
    every minor tick of a short log axis, and 0.6 .. 0.9 print over each other."""
    lo_dec, hi_dec = math.floor(math.log10(low)), math.ceil(math.log10(high))
    steps = (1.0, 2.0, 5.0) if hi_dec - lo_dec <= 3 else (1.0,)
    ticks = []
    for d in range(lo_dec, hi_dec + 1):
        for m in steps:
            v = m * 10.0 ** d
            if low / 1.05 <= v <= high * 1.05:
                ticks.append((math.log10(v), f"{v:g}"))
    return ticks


def _y_bounds(curves) -> tuple[float, float]:
    """The smallest and largest finite y drawn by `curves` (as drawn: log10 on a log axis); NaN if none."""
    lows, highs = [], []
    for curve in curves:
        y = curve.getData()[1]
        if y is not None and len(y):
            y = np.asarray(y, dtype=float)
            y = y[np.isfinite(y)]
            if len(y):
                lows.append(float(y.min()))
                highs.append(float(y.max()))
    return (min(lows), max(highs)) if lows else (math.nan, math.nan)


def _columns(columns: tuple[str, ...], data: np.ndarray, wanted: tuple[str, ...]) -> np.ndarray | None:
    """data's columns named `wanted`, in that order, or None if one is missing."""
    try:
        idx = [columns.index(c) for c in wanted]
    except ValueError:
        return None
    return np.asarray(data, dtype=float)[:, idx]


class LivePlots(QWidget):
    """The plot area; feed it with `add_samples` and `set_fit`, it redraws itself.  `fpga` and
    `table` hold the whole run decimated (what is drawn), `recent` the last minute at full rate."""

    def __init__(self, parent: QWidget | None = None, *, history_s: float | None = None, rate_hz: float = 1000.0,
                 refresh_hz: float = 25.0, max_points: int = 1200,
                 recent_s: float = 60.0) -> None:
        super().__init__(parent)
        pg.setConfigOptions(antialias=False, background="w", foreground="k")
        # the whole run (or its last history_s), decimated as it arrives (drawn), and the last
        # recent_s at full rate
        self.fpga = MinMaxHistory(FPGA_COLS[1:], max_points, history_s)
        self.table = MinMaxHistory(TABLE_COLS[1:], max_points, history_s)
        self.recent = RingBuffer(int(recent_s * rate_hz), FPGA_COLS)
        self.sweep = RingBuffer(100_000, SWEEP_COLS)
        self.table_marks = RingBuffer(100_000, ("t_s", "rate_dps"))  # a procedure's own rate readings
        self.cvg = MinMaxHistory(("rate_dph",), max_points, history_s)  # the rate output, deg/h
        self.temps = RingBuffer(100_000, ("t_s", *TEMP_COLS))  # the records' chamber readings (NaN: not in the stream)
        self.chamber = MinMaxHistory(("air_c", "part_c"), max_points, history_s)  # the chamber stream
        self._angle_last: tuple[float, float] | None = None  # (t_s, angle_out_deg) of the last FPGA row
        self._amp_max = 0.0  # the largest wave amplitude of the run so far
        self.allan = np.empty((0, 2))
        self.layout_kind = "hrg"
        self.max_points = max_points
        self.fits: dict[str, dict[str, np.ndarray]] = {}
        self.refresh_count = 0
        self.refresh_times: deque[float] = deque(maxlen=2000)  # wall monotonic of each redraw
        self.refresh_cost_s: deque[float] = deque(maxlen=2000)
        self._dirty = False
        self._queued: dict[tuple[str, tuple[str, ...]], list[np.ndarray]] = {}  # FPGA blocks for the next frame
        self._theta_last_rad: float | None = None
        self._wave_phasor: tuple[complex | None, complex] = (None, 0j)  # _wave_present's carry
        self.cvg_breaks: list[float] = []  # times where the rate output's curve is broken (no held wave)
        self._cvg_last_held = True  # the last FPGA row's wave was held (force-to-rebalance output)
        self._cvg_t_drawn: float | None = None  # the time of the last whole-angle rate drawn
        self._cvg_ftr = False  # the run's output is the force-to-rebalance rate (not the wave angle)
        self._rate_bin_last = math.nan  # the RATE_SPAN_S bin of the last FPGA row (whole-angle rate)
        self.bryan_factor: float | None = None  # K: the whole-angle rate output is -dtheta/dt / K
        self.t0_s: float | None = 0.0  # the run's start on the bench clock: the time axes are time since then

        # one view per plot: a frame repaints only the plots whose data changed
        grid = QGridLayout(self)
        grid.setContentsMargins(0, 0, 0, 0)
        grid.setSpacing(2)
        self.views: list[pg.PlotWidget] = []

        def add_plot(row: int, col: int, title: str, colspan: int = 1) -> pg.PlotItem:
            w = pg.PlotWidget(title=title)
            grid.addWidget(w, row, col, 1, colspan)
            self.views.append(w)
            return w.getPlotItem()

        # legends are the titles (above the data, never over it); units are the streams' declared
        # ones (bench.streams; the FPGA's slow variables are in AGC setpoint units: "1")
        self.p_q = add_plot(0, 0, legend_title(*zip(("cx", "sx", "cy", "sy"), PEN_COLOURS, strict=True)))
        self.p_q.setLabel("left", "cx..sy", units="1")
        self.c_q = [self.p_q.plot(pen=pg.mkPen(c, width=1), name=n)
                    for c, n in zip(PEN_COLOURS, ("cx", "sx", "cy", "sy"), strict=True)]
        self.p_e = add_plot(0, 1, legend_title(("E (log)", "#1f77b4"), ("fit", FIT_COLOUR)))
        self.p_e.setLogMode(x=False, y=True)
        self.e_log = True  # E's axis: log over more than a decade, linear within one (_choose_e_scale)
        self.p_e.setLabel("left", "E", units="1")
        self.c_e = self.p_e.plot(pen=pg.mkPen("#1f77b4", width=1), name="E")
        self.c_fit = self.p_e.plot(pen=pg.mkPen(FIT_COLOUR, width=2, style=pg.QtCore.Qt.PenStyle.DashLine), name="fit")
        self.p_theta = add_plot(1, 0, legend_title((THETA_TITLE, "#9467bd")))
        self._theta_title = THETA_TITLE
        self.p_theta.setLabel("left", "\u03b8", units="deg")
        self.c_theta = self.p_theta.plot(pen=pg.mkPen("#9467bd", width=1), name="\u03b8", connect="finite")
        self.p_rate = add_plot(1, 1, legend_title(("table rate", "#8c564b")))
        self.p_rate.setLabel("left", "rate", units="deg/s")
        self.c_rate = self.p_rate.plot(pen=pg.mkPen("#8c564b", width=1), name="rate")
        self.c_rate_marks = self.p_rate.plot(pen=None, symbol="t", symbolSize=7, symbolBrush="#17becf",
                                             symbolPen=None, name="readings")
        self.p_amp = add_plot(2, 0, legend_title(("sweep amplitude", "#1f77b4"), ("model", FIT_COLOUR)))
        self.p_amp.setLabel("left", "amplitude", units="1")
        self.c_amp = self.p_amp.plot(pen=pg.mkPen("#1f77b4"), symbol="o", symbolSize=5, symbolBrush="#1f77b4",
                                     name="amplitude")
        self.c_amp_fit = self.p_amp.plot(pen=pg.mkPen(FIT_COLOUR, width=2), name="model")
        self.p_phase = add_plot(2, 1, legend_title(("sweep phase", "#ff7f0e"), ("model", FIT_COLOUR)))
        self.p_phase.setLabel("left", "phase", units="deg")
        self.c_phase = self.p_phase.plot(pen=pg.mkPen("#ff7f0e"), symbol="o", symbolSize=5, symbolBrush="#ff7f0e",
                                         name="phase")
        self.c_phase_fit = self.p_phase.plot(pen=pg.mkPen(FIT_COLOUR, width=2), name="model")
        self.p_cvg = add_plot(3, 0, legend_title(("rate output", "#2ca02c")), colspan=2)
        self.p_cvg.setLabel("left", "rate output", units="deg/h")
        self.c_cvg = self.p_cvg.plot(pen=pg.mkPen("#2ca02c", width=1), name="rate output")
        self.p_allan = add_plot(4, 0, legend_title(("Allan deviation", "#1f77b4"), ("95 % band", "#9ecae1")))
        self.p_allan.setLogMode(x=True, y=True)
        self.p_allan.setLabel("left", "σ(τ)", units="deg/h")
        self.p_allan.setLabel("bottom", "τ", units="s")
        self.c_allan = self.p_allan.plot(pen=pg.mkPen("#1f77b4", width=2), symbol="o", symbolSize=4,
                                         symbolBrush="#1f77b4", name="Allan deviation")
        self.c_allan_lo = self.p_allan.plot(pen=pg.mkPen("#9ecae1", width=1), name="low")
        self.c_allan_hi = self.p_allan.plot(pen=pg.mkPen("#9ecae1", width=1), name="high")
        self.p_temp = add_plot(2, 0, legend_title(*TEMP_PENS.values()), colspan=2)  # where a sweep's plots are
        self.p_temp.setLabel("left", "T", units="degC")
        self.c_temp = {}  # the set point as squares alone, the readings as lines through their points
        for c, (name, colour) in TEMP_PENS.items():
            marks_only = c == "setpoint_c"
            self.c_temp[c] = self.p_temp.plot(pen=None if marks_only else pg.mkPen(colour, width=1),
                                              symbol="s" if marks_only else None, symbolSize=8,
                                              symbolBrush=colour, symbolPen=None, name=name)
        from .plot_cursor import CursorReadout

        self.cursor_label = QLabel("hover over a plot: x and y under the pointer")
        self.cursor_label.setObjectName("cursor_readout")
        grid.addWidget(self.cursor_label, 5, 0, 1, 2)
        self.cursor = CursorReadout(self.views, ("cx..sy", "E", "\u03b8", "table rate", "sweep amplitude",
                                                 "sweep phase", "rate output", "Allan deviation", "temperature"),
                                     self.cursor_label)
        self.sweep_views = self.views[4:6]
        self.set_layout("hrg")
        # no grid: redrawing grid lines with the axes costs ~10 ms per plot per frame (raster)
        self.time_plots = (self.p_q, self.p_e, self.p_theta, self.p_rate, self.p_cvg, self.p_temp)
        for p in self.time_plots:
            p.setLabel("bottom", "t since the run started", units="s")
            p.enableAutoRange(x=False)
        self._x_range: tuple[float, float] | None = None
        self._y_ranges: dict[int, tuple[float, float]] = {}  # id(plot): the y range last set (_hold_y_range)
        for p in (self.p_amp, self.p_phase):
            p.setLabel("bottom", "f", units="Hz")
        self.p_allan.getAxis("bottom").enableAutoSIPrefix(False)
        for w in self.views:  # a fixed width: no relayout when the tick labels change
            axis = w.getPlotItem().getAxis("left")
            axis.setWidth(76)
            axis.enableAutoSIPrefix(False)  # V stays V (a log axis with a prefix would mislead)
            w.getPlotItem().getAxis("bottom").enableAutoSIPrefix(False)

        self.timer = QTimer(self)
        self.timer.setTimerType(Qt.TimerType.PreciseTimer)  # a coarse timer drifts late under load: fewer frames
        self.timer.setInterval(max(1, int(round(1000.0 / refresh_hz))))
        self.timer.timeout.connect(self.refresh)
        self.timer.start()

    # --- data in ---------------------------------------------------------------------------
    def declare(self, schema: StreamSchema) -> None:
        """A StreamDeclared: the plots that show a column of the stream take its declared unit."""
        shown = {("fpga", "cx"): (self.p_q, "cx..sy"), ("table", "rate_dps"): (self.p_rate, "rate_dps"),
                 ("sweep", "amplitude"): (self.p_amp, "amplitude"), ("sweep", "phase_deg"): (self.p_phase, "phase_deg"),
                 ("fpga", "theta_deg"): (self.p_theta, "\u03b8")}
        for col in schema.columns:
            plot, text = shown.get((schema.name, col.name), (None, ""))
            if plot is not None:  # a dimensionless column says so ("1"): every axis has its unit
                plot.setLabel("left", text, units=col.unit or "1")
            if (schema.name, col.name) == ("fpga", "cx"):  # E = cx^2 + sx^2 + cy^2 + sy^2
                self.p_e.setLabel("left", "E", units=squared_unit(col.unit))

    def set_origin(self, t0_s: float | None) -> None:
        """Time axes from here on are seconds since `t0_s` (the run's start), not bench time;
        None: since the first sample (a replay whose file does not say when the run began)."""
        self.t0_s = None if t0_s is None else float(t0_s)

    def clear(self) -> None:
        self.t0_s = 0.0
        self._queued = {}
        self.fpga.clear()
        self.table.clear()
        self.recent.clear()
        self.sweep.clear()
        self.table_marks.clear()
        self.p_rate.setTitle(legend_title(("table rate", "#8c564b")))
        self.cvg.clear()
        self.temps.clear()
        self.chamber.clear()
        self._angle_last = None
        self._amp_max = 0.0
        self.allan = np.empty((0, 2))
        self.fits.clear()
        self._theta_last_rad = None
        self._wave_phasor = (None, 0j)
        self.cvg_breaks = []
        self._cvg_last_held = True
        self._cvg_t_drawn = None
        self._cvg_ftr = False
        self._rate_bin_last = math.nan
        self._x_range = None
        self._y_ranges.clear()
        for p in self.time_plots:
            p.enableAutoRange(y=True)  # until the first data: then _hold_y_range
        self.set_layout(self.layout_kind)
        for c in (*self.c_q, self.c_e, self.c_fit, self.c_theta, self.c_rate, self.c_rate_marks, self.c_amp,
                  self.c_phase, self.c_amp_fit, self.c_phase_fit, self.c_cvg, self.c_allan, self.c_allan_lo,
                  self.c_allan_hi, *self.c_temp.values()):
            c.setData([], [])
        self._dirty = True

    def queue_samples(self, stream: str, columns: tuple[str, ...], data: np.ndarray) -> None:
        """The window's path: a slow-variable (cx..sy) block waits for the next frame and is then
        added with the others of its stream in one pass (`flush_samples`), so the per-block work
        (orbit elements, the wave test, the unwrap) is paid once a frame, not once a block; other
        streams (sparse: the table, a sweep's points, readings) are added at once."""
        if self.t0_s is None or not {"t_s", "cx"} <= set(columns):  # a replay's origin comes from the first block
            self.add_samples(stream, columns, data)
            return
        self._queued.setdefault((stream, tuple(columns)), []).append(np.asarray(data))
        self._dirty = True

    def flush_samples(self) -> None:
        """Add the queued blocks, each stream's joined in order (before a redraw, a run's start or end)."""
        queued, self._queued = self._queued, {}
        for (stream, columns), arrays in queued.items():
            self.add_samples(stream, columns, arrays[0] if len(arrays) == 1 else np.concatenate(arrays))

    def add_samples(self, stream: str, columns: tuple[str, ...], data: np.ndarray) -> None:
        """One SampleBlock's rows; streams and columns the plots do not show are ignored."""
        data = np.asarray(data, dtype=float)
        if data.ndim != 2 or data.shape[0] == 0:
            return
        columns = tuple(columns)
        if "t_s" in columns and self.t0_s is None:
            self.t0_s = float(data[0, columns.index("t_s")])
        if self.t0_s and "t_s" in columns:
            data = data.copy()
            data[:, columns.index("t_s")] -= self.t0_s
        t = _columns(columns, data, ("t_s",))
        q = _columns(columns, data, ("cx", "sx", "cy", "sy"))
        if t is not None and q is not None:
            el = orbit_elements(q)
            # the angle means something where a standing wave is there: its 4 theta phasor moves
            # smoothly (pickoff noise alone has none), with the quadrature small against the amplitude
            defined = self._wave_present(el["theta_rad"]) & bool(
                np.median(np.abs(el["k"]) / np.maximum(el["a"], 1e-300)) < 0.3)
            theta_deg = self._unwrapped_theta_deg(el["theta_rad"], defined)
            values = np.column_stack((q, el["E"], theta_deg))  # FPGA_COLS after t_s
            self.fpga.append(t[:, 0], values)
            self.recent.append(np.column_stack((t, values)))
            self._dirty = True
            if self.layout_kind in RATE_OUTPUT_LAYOUTS:
                self._add_rate_output(columns, data, t[:, 0], self._held_rows(columns, data, el))
        rate = _columns(columns, data, ("rate_dps",))
        if t is not None and rate is not None and stream == TABLE_STREAM:
            angle = _columns(columns, data, ("angle_deg",))
            angle = np.full((len(data), 1), np.nan) if angle is None else angle
            self.table.append(t[:, 0], np.column_stack((rate, angle)))  # TABLE_COLS[1:]
            self._dirty = True
        elif t is not None and rate is not None:  # a procedure's readings (table-spin's "hold"): markers
            self.table_marks.append(np.column_stack((t, rate)))
            self._dirty = True
        chamber = _columns(columns, data, CHAMBER_COLS)
        if t is not None and chamber is not None and stream == CHAMBER_STREAM:
            self.chamber.append(t[:, 0], chamber)
            self._dirty = True
        span = _columns(columns, data, ("t_start_s", "t_end_s"))
        if span is not None and any(c in columns for c in TEMP_COLS):  # a chamber procedure's record or segment
            nan = np.full(len(data), np.nan)
            readings = [data[:, columns.index(c)] if c in columns else nan for c in TEMP_COLS]
            self.temps.append(np.column_stack([span.mean(axis=1) - (self.t0_s or 0.0), *readings]))
            self._dirty = True
        allan = _columns(columns, data, ALLAN_COLS + ("adev_low_dph", "adev_high_dph"))
        if stream == ALLAN_STREAM and allan is not None:
            self.allan = allan
            self._dirty = True
            if self.layout_kind == "cvg":
                self.set_layout("cvg")
        sweep = _columns(columns, data, ("freq_hz", "amplitude"))
        if sweep is not None:
            phase = _columns(columns, data, ("phase_deg",))
            phase = np.full((len(data), 1), np.nan) if phase is None else phase
            self.sweep.append(np.column_stack((sweep, phase)))
            self._dirty = True
            if not self.sweep_shown:
                self._show_sweep(True)

    def set_bryan_factor(self, k: float | None) -> None:
        """K of the run (its `bryan_factor`, else the station's nominal): the whole-angle rate output
        is the wave's rate divided by -K, as the procedures read it (procedures.cvg_allan); unknown
        (None, 0): the wave's own rate is drawn and the title says so."""
        self.bryan_factor = float(k) if k and k > 0 else None
        title = (f"rate from the output, \u2212d\u03b8/dt \u00f7 K (K = {self.bryan_factor:g})" if self.bryan_factor
                 else "wave rate \u2212d\u03b8/dt (K unknown: not divided by it)")
        self.p_cvg.setTitle(legend_title((title, "#2ca02c")))

    def _held_rows(self, columns: tuple[str, ...], data: np.ndarray, el: dict[str, np.ndarray]) -> np.ndarray:
        """Per row: do the loops hold the wave, so the output is a rate?  The amplitude near the
        run's largest (not starting, not quenched away) with a small quadrature, the amplitude loop
        on (its force exactly 0: off, at a turn-on's start or the run's end, where the whole-angle
        output is reset) and not at its limit (a quench's first second, the wave still large)."""
        self._amp_max = max(self._amp_max, float(np.max(el["a"])))
        held = (el["a"] > 0.5 * self._amp_max) & (np.abs(el["k"]) < 0.3 * np.maximum(el["a"], 1e-300))
        amp_ctrl = _columns(columns, data, ("amp_ctrl",))
        if amp_ctrl is not None:
            held &= amp_ctrl[:, 0] != 0.0
        sat = _columns(columns, data, ("sat_flags",))
        if sat is not None:
            held &= sat[:, 0] == 0.0
        return held

    def _add_rate_output(self, columns: tuple[str, ...], data: np.ndarray, t: np.ndarray, held: np.ndarray) -> None:
        """The rate sensor's output in deg/h where the wave is held (`held`, a row mask): the FPGA's
        rate output in force-to-rebalance (where the rebalance loop gives one: exactly 0 is its
        loop off, a quench), else the whole-angle output's rate -d(angle_out)/dt / K between the
        first rows of consecutive RATE_SPAN_S bins of bench time, over held rows only (K:
        set_bryan_factor).  The bins are fixed in time, so the curve does not depend on how the
        rows were cut into blocks (the window adds them once a frame)."""
        ftr = _columns(columns, data, ("rate_out_dps",))
        angle = _columns(columns, data, ("angle_out_deg",))
        if ftr is not None and not self._cvg_ftr and np.any(ftr[held, 0] != 0.0):
            self._cvg_ftr = True  # the mode holds for the run (a block inside a quench reads 0 throughout)
            self.p_cvg.setTitle(legend_title((FTR_TITLE, "#2ca02c")))
        if ftr is not None and self._cvg_ftr:
            held = held & (ftr[:, 0] != 0.0)
            was_held = np.concatenate(([self._cvg_last_held], held[:-1]))
            self.cvg_breaks.extend(t[held & ~was_held].tolist())  # the first held row after unheld ones
            self._cvg_last_held = bool(held[-1])
            if np.any(held):
                self.cvg.append(t[held], 3600.0 * ftr[held, :1])
            return
        if angle is None:
            return
        bins = np.floor(t / RATE_SPAN_S)
        starts = np.flatnonzero(bins != np.concatenate(([self._rate_bin_last], bins[:-1])))  # a bin's first row
        self._rate_bin_last = float(bins[-1])
        prev = self._angle_last  # the last bin start before this block, if every row since was held
        if prev is not None:
            t_all, a_all, h_all = (np.concatenate(([prev[0]], t)), np.concatenate(([prev[1]], angle[:, 0])),
                                   np.concatenate(([True], held)))
            picks = np.concatenate(([0], starts + 1))
        else:
            t_all, a_all, h_all, picks = t, angle[:, 0], held, starts
        if len(picks):
            last = int(picks[-1])
            self._angle_last = (float(t_all[last]), float(a_all[last])) if bool(np.all(h_all[last:])) else None
        elif not np.all(held):
            self._angle_last = None
        if len(picks) < 2:
            return
        unheld = np.concatenate(([0], np.cumsum(~h_all)))  # unheld rows before each index
        gaps = unheld[picks[1:] + 1] - unheld[picks[:-1]]  # unheld rows within each span
        dt = np.diff(t_all[picks])
        ok = (dt > 0) & (gaps == 0)  # never across a quench or a start: only over held rows
        # the curve breaks where rates are missing: a rate whose span does not start at the last
        # rate drawn (the span before it was not held, or the last block ended without a held wave)
        joins_last = self._cvg_t_drawn == float(t_all[picks[0]])
        after_drawn = np.concatenate(([joins_last], ok[:-1]))
        self.cvg_breaks.extend(t_all[picks[1:]][ok & ~after_drawn].tolist())
        if np.any(ok):
            rate = -np.diff(a_all[picks])[ok] / dt[ok] * 3600.0 / (self.bryan_factor or 1.0)
            self.cvg.append(t_all[picks[1:]][ok], rate[:, None])
            self._cvg_t_drawn = float(t_all[picks[1:]][ok][-1])

    def _wave_present(self, theta_rad: np.ndarray) -> np.ndarray:
        """Per row: is there a wave whose angle means something?  The step of the 4 theta phasor
        from row to row, averaged (WAVE_COHERENCE_ALPHA, carried across blocks): a wave's steps
        line up (|mean| near 1, turning or not), pickoff noise alone gives random steps (|mean|
        about sqrt(alpha / 2), 0.12; above WAVE_COHERENCE_MIN once in ~1e7 rows)."""
        z = np.exp(4j * np.asarray(theta_rad, dtype=float))
        prev_z, prev_m = self._wave_phasor
        steps = z * np.conj(np.concatenate(([prev_z if prev_z is not None else z[0]], z[:-1])))
        m = exponential_mean(steps, WAVE_COHERENCE_ALPHA, prev_m)
        self._wave_phasor = (complex(z[-1]), complex(m[-1]))
        return np.abs(m) > WAVE_COHERENCE_MIN

    def _unwrapped_theta_deg(self, theta_rad: np.ndarray, defined: np.ndarray) -> np.ndarray:
        """theta continues across its (-45, 45] deg wrap while a standing wave is there (a
        precessing wave is a line, not a saw); rows without a wave are NaN (not drawn: noise has
        no angle), and the angle starts afresh, wrapped, where a wave comes back."""
        out = np.full(len(theta_rad), np.nan)
        # runs of rows with a wave: [start, end) pairs
        edges = np.flatnonzero(np.diff(np.concatenate(([0], defined.astype(np.int8), [0]))))
        for start, end in zip(edges[0::2], edges[1::2], strict=True):
            prev = self._theta_last_rad if start == 0 else None
            seg = theta_rad[start:end]
            joined = np.unwrap(np.concatenate(([prev if prev is not None else seg[0]], seg)), period=np.pi / 2)
            if prev is not None:
                joined += prev - joined[0]
            out[start:end] = joined[1:]
        self._theta_last_rad = float(out[-1]) if len(out) and defined[-1] else None
        return np.degrees(out)

    def _pick_fit(self, x_key: str, y_keys: tuple[str, ...], prefer: str = "") -> tuple[np.ndarray, np.ndarray] | None:
        """(x, y) of the fit to overlay: the one named `prefer` if any, else the latest with x_key
        and one of y_keys (in that order of preference)."""
        names = list(self.fits)
        if prefer in self.fits:
            names.append(prefer)
        found = None
        for name in names:
            curves = self.fits[name]
            for key in y_keys:
                if x_key in curves and key in curves and len(curves[key]) == len(curves[x_key]):
                    found = (curves[x_key], curves[key])
                    break
        return found

    def set_fit(self, name: str, curves: dict[str, np.ndarray]) -> None:
        """A FitUpdate: an E(t) model ({t_s, E_fit | energy_fit | E}) or a sweep model
        ({freq_hz, amplitude[, phase_deg]}; the one named "sweep_model" wins)."""
        self.fits[name] = {k: np.asarray(v, dtype=float) for k, v in curves.items()}
        if "t_s" in self.fits[name]:
            self.fits[name]["t_s"] = self.fits[name]["t_s"] - (self.t0_s or 0.0)
        self._dirty = True

    # --- drawing ---------------------------------------------------------------------------
    def refresh(self, force: bool = False) -> None:
        """Redraw from the buffers (the timer calls it; nothing happens when nothing changed)."""
        if not (self._dirty or force):
            return
        t0 = time.perf_counter()
        self.flush_samples()
        self._dirty = False
        self._update_x_range()
        if len(self.fpga):
            for name, curve in zip(("cx", "sx", "cy", "sy"), self.c_q, strict=True):
                curve.setData(*self.fpga.curve(name))
            e_t, e_v = self.fpga.curve("E", positive_only=True)
            self.c_e.setData(e_t, e_v)
            self._choose_e_scale(e_v)
            th_t, th_deg = self.fpga.curve("theta_deg")
            wave = bool(np.isfinite(th_deg).any())
            # no wave at all: an empty curve (all-NaN data would pull the plot's x range off the run's)
            self.c_theta.setData(th_t if wave else [], th_deg if wave else [])
            self._set_theta_title(THETA_TITLE if wave else NO_WAVE_TITLE)
        if len(self.table):
            self.c_rate.setData(*self.table.curve("rate_dps"))
        if len(self.table_marks):
            self.c_rate_marks.setData(self.table_marks.column("t_s"), self.table_marks.column("rate_dps"))
            self.p_rate.setTitle(legend_title(("table rate", "#8c564b"), ("procedure's readings", "#17becf")))
        if len(self.cvg):
            t_cvg, r_cvg = self.cvg.curve("rate_dph")
            self.c_cvg.setData(t_cvg, r_cvg, connect=self._cvg_connect(t_cvg))
            self._robust_y_range(r_cvg)
        if len(self.temps):
            t_temp = self.temps.column("t_s")
            for c, curve in self.c_temp.items():
                if c == "setpoint_c" or not len(self.chamber):
                    y = self.temps.column(c)
                    ok = np.isfinite(y)
                    curve.setData(t_temp[ok], y[ok])
        if len(self.chamber):  # the live readings, as lines
            for c in ("air_c", "part_c"):
                self.c_temp[c].setData(*self.chamber.curve(c))
        if len(self.allan):
            ok = np.all(np.isfinite(self.allan) & (self.allan > 0), axis=1)
            tau, adev, lo, hi = self.allan[ok].T
            self.c_allan.setData(tau, adev)
            self.c_allan_lo.setData(tau, lo)
            self.c_allan_hi.setData(tau, hi)
            if len(tau):
                self.p_allan.getAxis("left").setTicks([log_ticks(float(np.min(lo)), float(np.max(hi))), []])
        if len(self.sweep):
            f, amp, phase = (self.sweep.column(c) for c in SWEEP_COLS)
            order = np.argsort(f, kind="stable")
            self.c_amp.setData(f[order], amp[order])
            if np.isfinite(phase).any():
                self.c_phase.setData(f[order], phase[order])
        e_fit = self._pick_fit("t_s", E_FIT_KEYS)
        if e_fit is not None:
            x, y = e_fit
            ok = y > 0
            self.c_fit.setData(x[ok], y[ok])
        amp_fit = self._pick_fit("freq_hz", ("amplitude",), prefer="sweep_model")
        if amp_fit is not None:
            self.c_amp_fit.setData(*amp_fit)
        phase_fit = self._pick_fit("freq_hz", ("phase_deg",), prefer="sweep_model")
        if phase_fit is not None:
            self.c_phase_fit.setData(*phase_fit)
        for plot, curves in ((self.p_q, self.c_q), (self.p_e, (self.c_e, self.c_fit)), (self.p_theta, (self.c_theta,)),
                             (self.p_rate, (self.c_rate, self.c_rate_marks)), (self.p_temp, self.c_temp.values())):
            self._hold_y_range(plot, *_y_bounds(curves))
        self.refresh_count += 1
        now = time.perf_counter()
        self.refresh_times.append(now)
        self.refresh_cost_s.append(now - t0)

    def _set_theta_title(self, title: str) -> None:
        if title != self._theta_title:
            self._theta_title = title
            self.p_theta.setTitle(legend_title((title, "#9467bd")))

    def _cvg_connect(self, t: np.ndarray) -> np.ndarray:
        """Which drawn rate points join the next: none across a break (a quench, a start)."""
        breaks = np.asarray(self.cvg_breaks)
        before = np.searchsorted(breaks, t, side="right")  # breaks at or before each point
        return np.concatenate((before[1:] == before[:-1], [False]))

    def _robust_y_range(self, y: np.ndarray) -> None:
        """The rate output's y axis over the 1st..99th percentile (padded): a wave-angle output's
        reset at a mode change (one sample of 1e7 deg/h) must not flatten the rate noise to a line."""
        y = y[np.isfinite(y)]
        if not len(y):
            return
        lo, hi = np.percentile(y, [1.0, 99.0]) if len(y) >= 20 else (np.min(y), np.max(y))
        self._hold_y_range(self.p_cvg, float(lo), float(hi), pad=0.15)

    def _hold_y_range(self, plot: pg.PlotItem, lo: float, hi: float, pad: float = Y_PAD) -> None:
        """The y axis over [lo, hi] (padded), moved only when the data leave it or fill less than
        Y_FILL_MIN of it: pyqtgraph's auto-range moved it every frame, and each move regenerates
        the axis's ticks (the largest part of a frame at "max").  A range the operator zoomed or
        panned to is left alone (the plot's own auto-range button takes over again)."""
        if not (math.isfinite(lo) and math.isfinite(hi)):
            return
        r0, r1 = plot.getViewBox().viewRange()[1]
        mine = self._y_ranges.get(id(plot))
        if mine is not None and not (math.isclose(r0, mine[0], rel_tol=1e-9, abs_tol=1e-12)
                                     and math.isclose(r1, mine[1], rel_tol=1e-9, abs_tol=1e-12)):
            return  # the operator's range
        span = max(hi - lo, 1e-6 * max(abs(lo), abs(hi)), 1e-12)
        inside = mine is not None and r0 <= lo and hi <= r1
        if inside and span >= Y_FILL_MIN * (r1 - r0):
            return
        if mine is not None and not inside:  # growing (a precessing angle, a rising temperature): room ahead
            lo, hi = (lo - Y_AHEAD * span if lo < r0 else lo), (hi + Y_AHEAD * span if hi > r1 else hi)
            span = hi - lo
        mid = 0.5 * (lo + hi)
        half = 0.5 * span * (1.0 + 2.0 * pad)
        plot.setYRange(mid - half, mid + half, padding=0.0)
        self._y_ranges[id(plot)] = tuple(plot.getViewBox().viewRange()[1])

    def _choose_e_scale(self, e: np.ndarray) -> None:
        """E on a log axis when, once excited, it spans more than a decade (a decay into the noise),
        else linear: a log axis over less than a decade has one tick or none, and the values cannot
        be read."""
        if not len(e):
            return
        # from the wave's excitation on (E first at half its largest): the climb from nothing at a
        # run's start spans ten decades and would put a held wave's flat E on a log axis
        e = e[int(np.argmax(e >= 0.5 * e.max())):]
        span = float(e.max() / max(e.min(), 1e-300))
        log = self.e_log
        if log and span < E_LINEAR_BELOW:
            log = False
        elif not log and span > E_LOG_ABOVE:
            log = True
        if log != self.e_log:
            self.e_log = log
            self.p_e.setLogMode(x=False, y=log)
            self._y_ranges.pop(id(self.p_e), None)  # the axis's units changed: a new range
            self.p_e.setTitle(legend_title(("E (log)" if log else "E", "#1f77b4"), ("fit", FIT_COLOUR)))

    def _show_sweep(self, shown: bool) -> None:
        """A sweep's points on a run laid out for another kind: its two plots join the others."""
        self.sweep_shown = shown
        for w in self.sweep_views:
            w.setVisible(shown)

    def set_layout(self, kind: str) -> None:
        """Show the plots of a kind of run (LAYOUTS: 'hrg', 'sweep', 'cvg'), hide the rest; the
        shown ones share the whole area.  A CVG run's Allan plot appears with its curve."""
        self.layout_kind = kind if kind in LAYOUTS else "hrg"
        shown = set(LAYOUTS[self.layout_kind])
        if self.layout_kind == "cvg" and not len(self.allan):
            shown.discard("p_allan")
        for attr in PLOT_ATTRS:
            self.views[self._view_index(attr)].setVisible(attr in shown)
        self.sweep_shown = "p_amp" in shown
        # a CVG run: the table's rate under the rate output (beside the Allan curve once it is there)
        cell = (1, 1, 1, 1) if self.layout_kind != "cvg" else (4, 1, 1, 1) if "p_allan" in shown else (4, 0, 1, 2)
        grid = self.layout()
        rate_view = self.views[self._view_index("p_rate")]
        grid.removeWidget(rate_view)
        grid.addWidget(rate_view, *cell)

    def _view_index(self, attr: str) -> int:
        return PLOT_ATTRS.index(attr)

    def _update_x_range(self) -> None:
        """The time axes move in round steps (not every frame): regenerating the ticks of four
        axes each frame would cost more than drawing the curves.  A growing run's axis is
        extended a third ahead (a few moves a run, not one each step); `fit_time_axes` ends it
        tight."""
        starts = [h.t_first for h in (self.fpga, self.table, self.chamber) if len(h)]
        ends = [h.t_last for h in (self.fpga, self.table, self.chamber) if len(h)]
        if not ends:
            return
        t0, t1 = min(starts), max(ends)
        if self._x_range is not None and self._x_range[0] <= t0 and t1 <= self._x_range[1]:
            return
        span = max(t1 - t0, 1e-3)
        step = 0.5 * 10.0 ** math.floor(math.log10(span))
        ahead = X_AHEAD if self._x_range is not None else 1.0  # the first range is the data's
        hi = t0 + max(1, math.ceil(ahead * span / step - 1e-9)) * step
        self._x_range = (t0, hi)
        for p in self.time_plots:
            p.setXRange(t0, hi, padding=0.0)

    def fit_time_axes(self) -> None:
        """The time axes over the data alone (a finished run: no room left ahead)."""
        self.flush_samples()
        self._x_range = None
        self._update_x_range()

    def set_refresh_hz(self, hz: float) -> None:
        """Redraws per second from now on (the window draws less often at "max" speed, where each
        frame's Python painting takes the interpreter from the engine's thread)."""
        self.timer.setInterval(max(1, int(round(1000.0 / hz))))

    def shutdown(self) -> None:
        """Stop redrawing and release the scene explicitly: left to the garbage collector, the
        pyqtgraph scene can be torn down in the wrong order at interpreter exit."""
        self.timer.stop()
        for w in self.views:
            w.getPlotItem().clear()
            w.close()

    def refresh_rate_hz(self, window_s: float = 2.0) -> float:
        """Redraws per second over the last window_s of wall time."""
        if len(self.refresh_times) < 2:
            return 0.0
        now = time.perf_counter()
        recent = [t for t in self.refresh_times if now - t <= window_s]
        if len(recent) < 2:
            return 0.0
        return (len(recent) - 1) / (recent[-1] - recent[0])
