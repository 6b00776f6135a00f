"""Cursor read-out for the live plots: hovering over a plot shows x and y under the pointer (a
log axis in its own values, not decades) and each curve's value at the nearest drawn sample,
with the axes' units, in one label under the plots.  Work is done only on mouse moves."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pyqtgraph as pg
from PySide6.QtWidgets import QLabel


def _axis_units(plot: pg.PlotItem, side: str) -> str:
    units = plot.getAxis(side).labelUnits or ""
    return f" {units}" if units and units != "1" else ""


def _fmt(v: float) -> str:
    return "-" if not math.isfinite(v) else f"{v:.6g}"


class CursorReadout:
    """Connects each plot's scene to `label`; `names[i]` is what plot i is called in the text."""

    def __init__(self, views: Sequence[pg.PlotWidget], names: Sequence[str], label: QLabel) -> None:
        self.label = label
        self.views = list(views)
        self.names = list(names)
        self.last_text = ""
        for view in self.views:
            view.scene().sigMouseMoved.connect(lambda pos, view=view: self.hover(view, pos))

    def hover(self, view: pg.PlotWidget, scene_pos) -> str:
        """Show what lies under the pointer at `scene_pos` (scene coordinates) of `view`."""
        plot = view.getPlotItem()
        vb = plot.getViewBox()
        if not vb.sceneBoundingRect().contains(scene_pos):
            return self.last_text
        pt = vb.mapSceneToView(scene_pos)
        return self.show_at(view, pt.x(), pt.y())

    def show_at(self, view: pg.PlotWidget, x: float, y_view: float) -> str:
        """The read-out at view coordinates (x, y as drawn: log10 of y on a log axis)."""
        plot = view.getPlotItem()
        log_y = bool(plot.ctrl.logYCheck.isChecked())
        y = 10.0 ** y_view if log_y else y_view
        xu, yu = _axis_units(plot, "bottom"), _axis_units(plot, "left")
        name = self.names[self.views.index(view)] if view in self.views else ""
        parts = [f"{name}: x = {_fmt(x)}{xu}, y = {_fmt(y)}{yu}"]
        near = []
        for curve in plot.listDataItems():
            xs, ys = curve.getData()
            if xs is None or len(xs) == 0:
                continue
            i = int(np.clip(np.searchsorted(xs, x), 1, len(xs) - 1)) if len(xs) > 1 else 0
            if len(xs) > 1 and abs(xs[i - 1] - x) < abs(xs[i] - x):
                i -= 1
            label = curve.name() or "curve"
            yi = 10.0 ** float(ys[i]) if log_y else float(ys[i])  # getData gives what is drawn (log10)
            near.append(f"{label} {_fmt(yi)}")
        if near:
            parts.append("nearest: " + ", ".join(near))
        self.last_text = "   ".join(parts)
        self.label.setText(self.last_text)
        return self.last_text
