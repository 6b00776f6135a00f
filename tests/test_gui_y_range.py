"""The live plots' y axes move in steps, not every frame (offscreen): pyqtgraph's auto-range moved
them with every new sample, and each move regenerated the axis's ticks, the largest part of a
frame at "max" (benchmarks/gui_max_speed.py --profile).  A y range holds while the data stay inside
it and fill at least half of it; data outside widen it; a range the operator zoomed to is kept."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pytestqt")
pytest.importorskip("pyqtgraph")

COLS = ("t_s", "cx", "sx", "cy", "sy")


def _rows(t: np.ndarray, cx: np.ndarray) -> np.ndarray:
    z = np.zeros_like(t)
    return np.column_stack((t, cx, z, z, z))


def _y_range(plot) -> tuple[float, float]:
    return tuple(plot.getViewBox().viewRange()[1])


def test_y_range_holds_while_the_data_stay_inside(plots):
    plots.clear()
    t = np.arange(0.0, 10.0, 0.01)
    plots.add_samples("fpga", COLS, _rows(t, 0.9 + 0.1 * np.sin(t)))
    plots.refresh(force=True)
    first = _y_range(plots.p_q)
    assert first[0] <= 0.0 and first[1] >= 1.0  # cx in 0.8..1, sx..sy at 0
    moves = []  # each move regenerates the axis's ticks at the next paint
    plots.p_q.getViewBox().sigYRangeChanged.connect(lambda *_: moves.append(1))
    for k in range(1, 5):  # more samples, a little beyond the last ones but inside the range: nothing moves
        tk = t + 10.0 * k
        plots.add_samples("fpga", COLS, _rows(tk, 0.9 + (0.1 + 0.01 * k) * np.sin(tk)))
        plots.refresh(force=True)
        assert _y_range(plots.p_q) == first
    assert moves == []
    t2 = t + 60.0
    plots.add_samples("fpga", COLS, _rows(t2, np.full_like(t2, 1.6)))  # above it: the range widens
    plots.refresh(force=True)
    lo, hi = _y_range(plots.p_q)
    assert lo <= 0.0 and hi >= 1.6 and (lo, hi) != first


def test_y_range_follows_a_shrinking_signal_and_keeps_the_operators_zoom(plots):
    plots.clear()
    t = np.arange(0.0, 10.0, 0.01)
    plots.add_samples("table", ("t_s", "rate_dps", "angle_deg"), np.column_stack((t, 100.0 * np.sin(t), t)))
    plots.refresh(force=True)
    lo, hi = _y_range(plots.p_rate)
    assert lo <= -99.0 and hi >= 99.0
    plots.clear()
    plots.add_samples("table", ("t_s", "rate_dps", "angle_deg"), np.column_stack((t, np.sin(t), t)))
    plots.refresh(force=True)
    lo, hi = _y_range(plots.p_rate)
    assert -1.5 < lo <= -0.99 and 0.99 <= hi < 1.5  # a new run: its own range, not the last one's
    plots.p_rate.setYRange(-0.2, 0.2, padding=0.0)  # the operator zooms in
    t2 = t + 10.0
    plots.add_samples("table", ("t_s", "rate_dps", "angle_deg"), np.column_stack((t2, 5.0 * np.sin(t2), t2)))
    plots.refresh(force=True)
    assert _y_range(plots.p_rate) == pytest.approx((-0.2, 0.2))


def test_a_growing_run_moves_its_time_axes_a_few_times_and_ends_tight(plots):
    """A live run's time axis is extended a third ahead (fewer moves: each regenerates the ticks
    of every time plot); the finished run's axis ends at its data (fit_time_axes, at RunFinished)."""
    plots.clear()
    moves = []
    plots.p_q.getViewBox().sigXRangeChanged.connect(lambda *_: moves.append(plots.p_q.getViewBox().viewRange()[0]))
    for k in range(100):  # 1000 s in 10 s blocks, a frame each
        t = np.arange(10.0 * k, 10.0 * (k + 1), 0.01)
        plots.add_samples("fpga", COLS, _rows(t, np.ones_like(t)))
        plots.refresh(force=True)
        lo, hi = plots.p_q.getViewBox().viewRange()[0]
        assert lo == pytest.approx(0.0) and hi >= t[-1]  # every sample on the axis
    assert len(moves) <= 20  # 27 when each move gave room for one round step only
    assert plots.p_q.getViewBox().viewRange()[0][1] > 1000.0
    plots.fit_time_axes()
    assert plots.p_q.getViewBox().viewRange()[0] == pytest.approx([0.0, 1000.0])
