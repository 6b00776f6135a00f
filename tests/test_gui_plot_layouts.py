"""The live plots follow the procedure (offscreen): the table-rate curve is the table's own rate
stream (a procedure's readings, table-spin's "hold", are separate markers, never joined into the
curve); a sweep shows its two sweep plots large and hides the HRG ones; a CVG run gets its rate
output live and the Allan curve once the procedure records it."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pytestqt")
pytest.importorskip("pyqtgraph")

from bench.gui.plots import layout_for  # noqa: E402


def test_hold_readings_are_markers_not_part_of_the_table_curve(plots):
    t = np.linspace(0.0, 10.0, 101)
    plots.add_samples("table", ("t_s", "rate_dps", "angle_deg"), np.column_stack((t, np.full_like(t, 100.0), t)))
    hold = np.array([[2.0, 99.9], [4.0, 100.1], [6.0, 100.0]])
    plots.add_samples("hold", ("t_s", "rate_dps"), hold)
    plots.refresh(force=True)
    x, y = plots.c_rate.getData()
    assert len(x) > 0 and np.all(np.diff(x) >= 0)  # one curve in time order: no triangle back to t = 2
    assert set(np.round(y, 6)) == {100.0}
    mx, my = plots.c_rate_marks.getData()
    np.testing.assert_allclose(mx, hold[:, 0])
    np.testing.assert_allclose(my, hold[:, 1])


def test_layout_follows_the_procedure(plots):
    assert (layout_for("mems-sweep"), layout_for("cvg-bias"), layout_for("cvg-allan"),
            layout_for("hrg-damping"), layout_for("table-spin")) == ("sweep", "cvg", "cvg", "hrg", "hrg")
    names = ("p_q", "p_e", "p_theta", "p_rate", "p_amp", "p_phase", "p_cvg", "p_allan")

    def shown():
        return {n for n in names if plots.views[names.index(n)].isVisible()}

    plots.set_layout("sweep")
    assert shown() == {"p_amp", "p_phase"}
    amp_view = plots.views[names.index("p_amp")]
    assert amp_view.height() > 0.35 * plots.height()  # large: the sweep plots share the whole area
    plots.set_layout("hrg")
    assert shown() == {"p_q", "p_e", "p_theta", "p_rate"}
    plots.set_layout("cvg")
    assert shown() == {"p_cvg", "p_rate"}


def test_cvg_rate_output_live_and_the_allan_curve_when_recorded(plots):
    plots.set_layout("cvg")
    plots.clear()
    t = np.arange(0.0, 100.0, 0.01)
    angle = -2.0 / 3600.0 * t  # the wave turning at -2 deg/h: output-referred rate 2 deg/h
    cols = ("t_s", "cx", "sx", "cy", "sy", "angle_out_deg", "rate_out_dps")
    rows = np.column_stack((t, np.ones_like(t), 0 * t, 0 * t, 0 * t, angle, 0 * t))
    plots.add_samples("fpga", cols, rows[:5001])
    plots.add_samples("fpga", cols, rows[5001:])  # across blocks: no gap, no jump
    plots.refresh(force=True)
    x, y = plots.c_cvg.getData()
    assert len(x) >= 200  # one rate each RATE_SPAN_S (0.1 s), drawn as a bounded envelope
    np.testing.assert_allclose(y, 2.0, rtol=1e-6)
    jump = rows[-1:].copy()
    jump[0, 0] += 0.01
    jump[0, 5] += 300.0  # the output's reset at a mode change: one huge "rate"
    plots.add_samples("fpga", cols, jump)
    plots.refresh(force=True)
    lo, hi = plots.p_cvg.getViewBox().viewRange()[1]
    assert lo < 2.0 < hi and hi - lo < 1.0  # the axis stays on the rate, not on the one reset
    tau = np.array([1.0, 10.0, 100.0])
    curve = np.column_stack((tau, [3.0, 1.0, 0.8], [2.5, 0.8, 0.5], [3.5, 1.3, 1.4], [100, 10, 1]))
    plots.add_samples("cvg_allan_curve", ("tau_s", "adev_dph", "adev_low_dph", "adev_high_dph", "clusters"), curve)
    plots.refresh(force=True)
    names = ("p_q", "p_e", "p_theta", "p_rate", "p_amp", "p_phase", "p_cvg", "p_allan")
    assert plots.views[names.index("p_allan")].isVisible()
    np.testing.assert_allclose(plots.c_allan.yData, [3.0, 1.0, 0.8])  # getData() gives log10 on a log axis
