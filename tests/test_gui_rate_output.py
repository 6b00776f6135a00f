"""The live rate output of the CVG procedures (offscreen), on rows shaped like the simulated
FPGA's (sim-hrg-ftr's cvg-bias, sim-hrg's cvg-scale-factor): as a quench starts the loops let go
of a wave that is still large (the rebalance output reads exactly 0, the AGC force sits at its
limit): no point is drawn there, so the curve does not dive to 0 before it breaks; at the run's
end the loops are off (the AGC force exactly 0) and the whole-angle output is reset: no reset
spike ends the curve.  The curve is the same however the rows were cut into blocks (the window
adds them once a frame)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pytestqt")
pytest.importorskip("pyqtgraph")

COLS = ("t_s", "cx", "sx", "cy", "sy", "amp_ctrl", "angle_out_deg", "rate_out_dps", "sat_flags")
RATE_DPH = 2.0  # the held output's rate (deg/h)
K = 0.277


def _rows(t, amplitude, amp_ctrl, angle_deg, rate_out_dps, sat) -> np.ndarray:
    z = np.zeros_like(t)
    return np.column_stack((t, amplitude, z, z, z, amp_ctrl, angle_deg, rate_out_dps, sat))


def _quench(t: np.ndarray, t_q: float = 50.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Amplitude, AGC force and saturation of a quench starting at t_q: the AGC set to 0 at its
    force limit, the amplitude falling 0.5 a second (as sim-hrg's), then 10 s quiet, then held again."""
    quench = (t >= t_q) & (t < t_q + 12.0)
    amplitude = np.where(quench, np.maximum(1.0 - 0.5 * (t - t_q), 0.001), 1.0)
    sat = (quench & (amplitude > 0.5)).astype(float)
    amp_ctrl = np.where(quench, np.where(sat > 0, -1.0, -2.0 * amplitude), 0.0067)
    return amplitude, amp_ctrl, sat


def _feed(plots, rows: np.ndarray, block: int) -> None:
    for i in range(0, len(rows), block):
        plots.add_samples("fpga", COLS, rows[i:i + block])
    plots.refresh(force=True)


def test_force_to_rebalance_output_breaks_at_the_quench_without_a_dive(plots):
    plots.set_layout("cvg")
    plots.clear()
    t = np.arange(0.0, 100.0, 0.01)
    amplitude, amp_ctrl, sat = _quench(t)
    loops_off = (t >= 50.0) & (t < 62.0)
    rate = np.where(loops_off, 0.0, RATE_DPH / 3600.0)  # the rebalance loop off: its output reads 0
    _feed(plots, _rows(t, amplitude, amp_ctrl, -0.0 * t, rate, sat), 100)
    x, y = plots.c_cvg.getData()
    assert x.min() < 50.0 and x.max() > 62.0
    np.testing.assert_allclose(y, RATE_DPH, rtol=1e-5)  # no point at 0 deg/h: no dive
    assert not np.any((x >= 50.0) & (x < 62.0))


def test_whole_angle_output_has_no_reset_spike_when_the_loops_stop(plots):
    plots.set_layout("cvg")
    plots.set_bryan_factor(K)
    plots.clear()
    plots.set_bryan_factor(K)
    t = np.arange(0.0, 60.0, 0.01)
    angle = 180.0 - RATE_DPH * K / 3600.0 * t
    off = t >= 59.5  # the safe state: the loops off (AGC force exactly 0) and the output reset
    angle = np.where(off, 0.8, angle)
    amp_ctrl = np.where(off, 0.0, 0.0067)
    rows = _rows(t, np.ones_like(t), amp_ctrl, angle, 0.0 * t, 0.0 * t)
    _feed(plots, rows, 37)
    x, y = plots.c_cvg.getData()
    assert x.max() < 59.6
    np.testing.assert_allclose(y, RATE_DPH, rtol=1e-4)  # no 2e7 deg/h point at the end


def test_whole_angle_output_breaks_at_the_quench_without_a_dive(plots):
    plots.set_layout("cvg")
    plots.clear()
    plots.set_bryan_factor(K)
    t = np.arange(0.0, 100.0, 0.01)
    amplitude, amp_ctrl, sat = _quench(t)
    angle = -RATE_DPH * K / 3600.0 * t
    quench = (t >= 50.0) & (t < 62.0)
    angle = np.where(quench, angle + 0.05 * np.sin(7.0 * (t - 50.0)), angle)  # the loops let go: the angle wanders
    _feed(plots, _rows(t, amplitude, amp_ctrl, angle, 0.0 * t, sat), 100)
    x, y = plots.c_cvg.getData()
    np.testing.assert_allclose(y, RATE_DPH, rtol=1e-4)
    assert not np.any((x > 50.0) & (x < 62.0))


@pytest.mark.parametrize("output", ["whole-angle", "force-to-rebalance"])
def test_the_rate_curve_does_not_depend_on_the_blocks(plots, output):
    """Blocks of any size, or joined once a frame (queue_samples, flush at the redraw): the same
    points, the same breaks."""
    from bench.gui.plots import LivePlots

    t = np.arange(0.0, 100.0, 0.01)
    amplitude, amp_ctrl, sat = _quench(t)
    rng = np.random.default_rng(3)
    angle = -RATE_DPH * K / 3600.0 * t + rng.normal(0.0, 1e-4, len(t))
    rate = (RATE_DPH + rng.normal(0.0, 0.5, len(t))) / 3600.0 if output != "whole-angle" else 0.0 * t
    rate = np.where((t >= 50.0) & (t < 62.0), 0.0, rate)
    rows = _rows(t, amplitude, amp_ctrl, angle, rate, sat)
    curves = []
    for sizes in ((100,), (1, 7, 333, 50, 999), (len(rows),)):
        p = LivePlots(max_points=100_000)
        try:
            p.set_layout("cvg")
            p.clear()
            p.set_bryan_factor(K)
            i, k = 0, 0
            while i < len(rows):
                n = sizes[k % len(sizes)]
                p.queue_samples("fpga", COLS, rows[i:i + n])
                if k % 3 == 2:
                    p.refresh(force=True)  # a frame
                i, k = i + n, k + 1
            p.refresh(force=True)
            curves.append((*p.cvg.curve("rate_dph"), np.array(p.cvg_breaks), p.fpga.total_rows))
        finally:
            p.shutdown()
    for x, y, breaks, n in curves[1:]:
        assert n == len(rows)  # nothing lost
        np.testing.assert_allclose(x, curves[0][0], atol=1e-12)
        np.testing.assert_allclose(y, curves[0][1], rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(breaks, curves[0][2], atol=1e-12)
