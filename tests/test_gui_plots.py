"""The live plots (offscreen): the cursor read-out gives x and y under the pointer (E's log axis
in E's own values) and each curve's nearest value; legends are the titles, above the data; every
axis carries the unit its stream declares (cx..sy, E, sweep amplitude too); a long record is drawn
from a min/max envelope of bounded size that keeps the extremes."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pytestqt")
pytest.importorskip("pyqtgraph")

import pyqtgraph as pg  # noqa: E402

from bench.gui.plots import FPGA_COLS  # noqa: E402
from drivers.fpga.protocol import STREAM_SCHEMA  # noqa: E402
from drivers.rate_table.base import TABLE_STREAM  # noqa: E402


def _decay(n: int, rate_hz: float = 1000.0) -> np.ndarray:
    t = np.arange(n) / rate_hz
    a = np.exp(-t / 300.0)
    return np.column_stack((t, a, np.zeros(n), np.zeros(n), np.zeros(n)))


def test_cursor_readout_gives_x_y_and_the_nearest_values(plots):
    plots.declare(STREAM_SCHEMA)
    plots.add_samples("fpga", FPGA_COLS[:5], _decay(20_000))
    plots.refresh(force=True)
    view_q, view_e = plots.views[0], plots.views[1]
    text = plots.cursor.show_at(view_q, 10.0, 0.5)
    assert text.startswith("cx..sy: x = 10 s, y = 0.5") and "cx 0.96" in text  # exp(-10/300) = 0.967
    # E within less than a decade is drawn on a linear axis (a log one would have one tick or none)
    assert not plots.e_log and plots.p_e.titleLabel.text.count("E (log)") == 0
    text = plots.cursor.show_at(view_e, 10.0, 0.9)
    assert "y = 0.9" in text and "E 0.93" in text  # E = a^2 = exp(-20/300) = 0.9355
    fast = _decay(20_000)
    fast[:, 0] += 20.0
    fast[:, 1] = np.exp(-fast[:, 0] / 2.0)  # into the noise: many decades, a log axis
    plots.add_samples("fpga", FPGA_COLS[:5], fast)
    plots.refresh(force=True)
    assert plots.e_log and "E (log)" in plots.p_e.titleLabel.text
    text = plots.cursor.show_at(view_e, 30.0, np.log10(1e-5))  # the log axis: E's own value, not a decade
    assert "y = 1e-05" in text
    e_near = float(text.split("nearest: E ")[1].split(",")[0])
    assert e_near == pytest.approx(np.exp(-30.0), rel=0.2)  # E = a^2 = exp(-t), at the nearest drawn sample
    assert plots.cursor_label.text() == text
    # a mouse move over the data box goes the same way
    vb = view_q.getPlotItem().getViewBox()
    pos = vb.mapViewToScene(pg.Point(5.0, 0.2))
    assert plots.cursor.hover(view_q, pos).startswith("cx..sy: x = 5")


def test_legends_are_outside_the_data_and_every_axis_has_its_declared_unit(plots):
    from procedures.mems_sweep import SWEEP

    for schema in (STREAM_SCHEMA, TABLE_STREAM, SWEEP):
        plots.declare(schema)
    for view in plots.views:
        item = view.getPlotItem()
        assert item.legend is None  # no legend box over the curves
        assert "<span" in item.titleLabel.text  # the title is the legend, each name in its pen's colour
        assert item.getAxis("left").labelUnits and item.getAxis("bottom").labelUnits
    assert plots.p_q.getAxis("left").labelUnits == "1"  # STREAM_SCHEMA: cx is in AGC setpoint units
    assert plots.p_e.getAxis("left").labelUnits == "1"
    assert plots.p_amp.getAxis("left").labelUnits == "1" and plots.p_phase.getAxis("left").labelUnits == "deg"
    assert plots.p_rate.getAxis("left").labelUnits == "deg/s"


def test_a_long_record_is_drawn_as_a_bounded_envelope_that_keeps_the_extremes(plots):
    n = 600_000  # 10 min at 1 kHz
    data = _decay(n)
    data[:, 1] = np.sin(2 * np.pi * 37.0 * data[:, 0])  # fast against a pixel: a solid band if drawn raw
    data[123_456, 1] = 3.0  # one spike must survive the decimation
    data[n - 100, 1] = -2.5  # and one in the newest rows, not yet in a bucket
    for k in range(0, n, 50_000):
        plots.add_samples("fpga", FPGA_COLS[:5], data[k:k + 50_000])
    plots.refresh(force=True)
    x, y = plots.c_q[0].getData()
    assert plots.fpga.total_rows == n
    assert len(x) <= 4 * plots.max_points
    assert y.max() == pytest.approx(3.0) and y.min() == pytest.approx(-2.5)
    assert np.all(np.diff(x) >= 0)  # in time order
