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


def _rate_rows(t: np.ndarray, amplitude: np.ndarray, angle_deg: np.ndarray, rate_out_dps: np.ndarray) -> np.ndarray:
    """FPGA rows (t_s, cx, sx, cy, sy, angle_out_deg, rate_out_dps) of a wave along x of the given amplitude."""
    z = np.zeros_like(t)
    return np.column_stack((t, amplitude, z, z, z, angle_deg, rate_out_dps))


def _joined_across(plots, t_from: float, t_to: float) -> bool:
    """Does the drawn rate-output curve join a point at or before t_from to one at or after t_to?"""
    x, _ = plots.c_cvg.getData()
    connect = plots.c_cvg.opts["connect"]
    connect = np.ones(len(x), bool) if isinstance(connect, str) else np.asarray(connect, bool)
    i = np.flatnonzero((x[:-1] <= t_from) & (x[1:] >= t_to))
    return bool(np.any(connect[i]))


@pytest.mark.parametrize("output", ["whole-angle", "force-to-rebalance"])
def test_cvg_rate_curve_breaks_at_a_quench(plots, output):
    """cvg-bias quenches the resonator between turn-ons: the live rate curve has no line over the
    quench (50..60 s here), fed in 1 s blocks; the held spans on either side stay joined."""
    plots.set_layout("cvg")
    plots.clear()
    t = np.arange(0.0, 100.0, 0.01)
    quench = (t > 50.0) & (t < 60.0)
    amplitude = np.where(quench, 0.001, 1.0)
    angle = -2.0 / 3600.0 * t + np.where(t >= 60.0, 5.0, 0.0)  # the wave comes back at another angle
    rate = np.zeros_like(t) if output == "whole-angle" else np.where(t >= 60.0, 3.0, 2.0) / 3600.0
    rows = _rate_rows(t, amplitude, angle, rate)
    cols = ("t_s", "cx", "sx", "cy", "sy", "angle_out_deg", "rate_out_dps")
    for i in range(0, len(t), 100):
        plots.add_samples("fpga", cols, rows[i:i + 100])
    plots.refresh(force=True)
    x, y = plots.c_cvg.getData()
    assert x.min() < 50.0 and x.max() > 60.0 and not np.any((x > 50.05) & (x < 60.0))
    assert not _joined_across(plots, 50.0, 60.0)  # no line over the quench
    assert _joined_across(plots, 20.0, 20.01) and _joined_across(plots, 80.0, 80.01)  # held spans are lines


def test_wave_angle_shows_nothing_on_pickoff_noise_and_the_angle_of_a_wave(plots):
    """table-spin runs with no wave (pickoff noise only): the wave-angle plot draws no angle and
    says why; a precessing wave is drawn as a line (unwrapped), fed in blocks of any length."""
    plots.clear()
    rng = np.random.default_rng(7)
    t = np.arange(0.0, 20.0, 0.001)
    noise = rng.normal(0.0, 1e-3, (len(t), 4))
    cols = ("t_s", "cx", "sx", "cy", "sy")
    for i, n in enumerate((1, 7, 50, 1000, 5000, 13942)):  # blocks of every size
        start = sum((1, 7, 50, 1000, 5000, 13942)[:i])
        plots.add_samples("fpga", cols, np.column_stack((t, noise))[start:start + n])
    plots.refresh(force=True)
    _, th = plots.c_theta.getData()
    assert th is None or not np.isfinite(th).any()
    assert "no standing wave" in plots.p_theta.titleLabel.text
    # the title fits above its plot (a long one was cut off at half the window's width)
    assert plots.p_theta.titleLabel.item.boundingRect().width() < 0.9 * plots.views[2].width()
    # then a wave turning at 30 deg/s: its angle, unwrapped, is drawn and the title is the plain one
    t2 = np.arange(20.0, 30.0, 0.001)
    theta = np.radians(30.0 * (t2 - 20.0))
    wave = np.column_stack((t2, np.cos(2 * theta), 0 * t2, np.sin(2 * theta), 0 * t2)) + np.column_stack(
        (0 * t2, rng.normal(0.0, 1e-3, (len(t2), 4))))
    for i in range(0, len(t2), 250):
        plots.add_samples("fpga", cols, wave[i:i + 250])
    plots.refresh(force=True)
    x, th = plots.c_theta.getData()
    late = x > 20.5
    assert np.isfinite(th[late]).all() and np.nanmax(th[late]) > 250.0  # a line up to ~300 deg, not a saw
    assert not np.isfinite(th[x < 19.9]).any()
    assert "no standing wave" not in plots.p_theta.titleLabel.text


def test_whole_angle_rate_output_is_the_waves_rate_divided_by_k(plots):
    """The live rate output reads as the procedures read the gyro's output (-dtheta/dt / K): the
    window drew the wave's own rate, 3.4 deg/h where cvg-allan's rate_mean_dph read 12.1."""
    plots.set_layout("cvg")
    plots.clear()
    plots.set_bryan_factor(0.277)
    t = np.arange(0.0, 20.0, 0.01)
    cols = ("t_s", "cx", "sx", "cy", "sy", "angle_out_deg", "rate_out_dps")
    plots.add_samples("fpga", cols, _rate_rows(t, np.ones_like(t), -3.4 / 3600.0 * t, 0 * t))
    plots.refresh(force=True)
    _, y = plots.c_cvg.getData()
    np.testing.assert_allclose(y, 3.4 / 0.277, rtol=1e-6)
    assert "\u00f7 K (K = 0.277)" in plots.p_cvg.titleLabel.text
    plots.set_bryan_factor(None)  # K unknown: the wave's rate, and the title says so
    assert "not divided" in plots.p_cvg.titleLabel.text


def test_allan_axis_labels_do_not_print_over_each_other(plots):
    """cvg-allan's curve from 0.09 to 3 deg/h: the y axis labelled 0.6, 0.7, 0.8, 0.9 over each other
    (pyqtgraph labels every minor tick of a short log axis); now 1, 2, 5 of each decade."""
    from bench.gui.plots import log_ticks

    plots.set_layout("cvg")
    tau = np.array([0.1, 1.0, 10.0, 100.0, 200.0])
    curve = np.column_stack((tau, [2.9, 0.7, 0.24, 0.17, 0.23], [2.7, 0.6, 0.2, 0.1, 0.09],
                             [3.1, 0.8, 0.3, 0.4, 1.9], [6000, 600, 60, 6, 3]))
    plots.add_samples("cvg_allan_curve", ("tau_s", "adev_dph", "adev_low_dph", "adev_high_dph", "clusters"), curve)
    plots.refresh(force=True)
    major = plots.p_allan.getAxis("left")._tickLevels[0]
    assert [label for _, label in major] == ["0.1", "0.2", "0.5", "1", "2"]
    positions = np.array([pos for pos, _ in major])
    assert np.all(np.diff(positions) >= np.log10(2.0) - 1e-9)  # a factor 2 apart at least: room for a label
    assert [lab for _, lab in log_ticks(0.01, 500.0)] == ["0.01", "0.1", "1", "10", "100"]


def test_a_held_wave_puts_e_on_a_linear_axis_despite_its_climb_from_nothing(plots):
    """hrg-selfcal holds E at 1 for half an hour after its excitation climbed from 1e-12: E was drawn
    on a log axis from 1e-12 to 1 (a flat line at the top); a decay still gets the log axis."""
    plots.clear()
    t = np.arange(0.0, 100.0, 0.01)
    a = np.minimum(1.0, np.exp((t - 5.0) * 5.0))  # the climb, then held
    cols = ("t_s", "cx", "sx", "cy", "sy")
    plots.add_samples("fpga", cols, np.column_stack((t, a, 0 * t, 0 * t, 0 * t)))
    plots.refresh(force=True)
    assert not plots.e_log
    t2 = np.arange(100.0, 1000.0, 0.1)
    plots.add_samples("fpga", cols, np.column_stack((t2, np.exp(-(t2 - 100.0) / 300.0), 0 * t2, 0 * t2, 0 * t2)))
    plots.refresh(force=True)
    assert plots.e_log  # E falls 400x in the decay


def test_the_wave_tests_running_mean_is_the_one_pole_filter_across_blocks():
    """exponential_mean (the wave test's mean step, carried from block to block) against scipy's
    lfilter of the same one-pole filter and its recurrence written out, for blocks shorter and
    longer than its chunk."""
    from scipy.signal import lfilter

    from bench.gui.plots import exponential_mean

    rng = np.random.default_rng(5)
    alpha, carry, direct = 0.03, 0.25 - 0.5j, 0.25 - 0.5j
    for n in (1, 7, 63, 64, 65, 130, 1000):
        x = np.exp(1j * rng.uniform(0.0, 2 * np.pi, n))
        got = exponential_mean(x, alpha, carry)
        ref = lfilter([alpha], [1.0, alpha - 1.0], x, zi=[(1.0 - alpha) * carry])[0]
        np.testing.assert_allclose(got, ref, rtol=0, atol=1e-14)
        for v in x:
            direct = alpha * v + (1.0 - alpha) * direct
        assert abs(got[-1] - direct) < 1e-13
        carry = complex(got[-1])
