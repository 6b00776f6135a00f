"""The procedures that drive the temperature chamber (thermal-soak, thermal-ramp) get a
temperature plot (offscreen): the chamber air and the case thermocouple live from the chamber's
stream (a row at every link check), the set points as the procedures record them with each record
(their streams' t_start_s .. t_end_s, drawn at the middle, on the run's time axis; a chamber
without a stream: the records' readings), beside the rate output; the HRG plots' angle and table
give way."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pytestqt")
pytest.importorskip("pyqtgraph")

from bench.gui.plots import PLOT_ATTRS, layout_for  # noqa: E402


def _shown(plots) -> set[str]:
    return {n for n in PLOT_ATTRS if plots.views[PLOT_ATTRS.index(n)].isVisible()}


def test_chamber_procedures_show_the_temperature_plot(plots):
    assert layout_for("thermal-soak") == layout_for("thermal-ramp") == "thermal"
    assert layout_for("hrg-damping") == "hrg" and layout_for("cvg-bias") == "cvg"
    plots.set_layout("thermal")
    assert {"p_temp", "p_cvg"} <= _shown(plots) and not {"p_theta", "p_amp", "p_allan"} & _shown(plots)
    temp_view = plots.views[PLOT_ATTRS.index("p_temp")]
    assert temp_view.height() > 0.2 * plots.height()
    assert plots.p_temp.getAxis("left").labelUnits == "degC"
    plots.set_layout("hrg")
    assert "p_temp" not in _shown(plots)


def test_soak_windows_and_ramp_segments_are_drawn_on_the_run_time_axis(plots):
    from procedures.thermal_ramp import SEGMENTS, VERIFY
    from procedures.thermal_soak import WINDOWS

    plots.set_layout("thermal")
    plots.clear()
    plots.set_origin(1000.0)  # the run started at bench time 1000 s
    soak = np.array([[1100.0, 1400.0, -40.0, -39.9, -39.5, 600.0, 5500.0, 1, 1.0],
                     [2100.0, 2400.0, 25.0, 25.1, 24.8, 500.0, 5500.0, 1, 1.0]])
    plots.add_samples(WINDOWS.name, WINDOWS.names, soak)
    seg = np.array([[2500.0, 2560.0, 0, 10.0, 30.0, 28.0, 5500.0, 1, 1.0],
                    [2560.0, 2620.0, 0, -10.0, 32.0, 29.5, 5500.0, 1, 1.0]])
    plots.add_samples(SEGMENTS.name, SEGMENTS.names, seg)
    verify = np.array([[2700.0, 2800.0, 40.0, 40.0, 39.9, 100.0, 5500.0, 1, 1.0, 0.0, 0.0]])
    plots.add_samples(VERIFY.name, VERIFY.names, verify)
    plots.refresh(force=True)
    x, y = plots.c_temp["air_c"].getData()
    np.testing.assert_allclose(x, [250.0, 1250.0, 1530.0, 1590.0, 1750.0])  # middles, since the run started
    np.testing.assert_allclose(y, [-39.9, 25.1, 30.0, 32.0, 40.0])
    x, y = plots.c_temp["part_c"].getData()
    np.testing.assert_allclose(y, [-39.5, 24.8, 28.0, 29.5, 39.9])
    x, y = plots.c_temp["setpoint_c"].getData()  # the segments carry no set point: none drawn for them
    np.testing.assert_allclose(x, [250.0, 1250.0, 1750.0])
    np.testing.assert_allclose(y, [-40.0, 25.0, 40.0])
    assert plots.table.total_rows == 0  # a segment's rate_dps is not the table's stream
    plots.clear()
    assert len(plots.temps) == 0 and len(plots.c_temp["air_c"].getData()[0] or ()) == 0


def test_the_chamber_stream_is_drawn_live(plots):
    from drivers.chamber.watlow_f4_spec import CHAMBER_STREAM
    from procedures.thermal_soak import WINDOWS

    plots.set_layout("thermal")
    plots.clear()
    plots.set_origin(1000.0)
    t = 1000.0 + np.arange(0.0, 600.0, 0.4)
    air = np.minimum(25.0 + 0.5 * (t - 1000.0), 85.0)
    part = 25.0 + 60.0 * (1.0 - np.exp(-(t - 1000.0) / 60.0))
    rows = np.column_stack((t, air, part))
    for i in range(0, len(rows), 5):
        plots.add_samples(CHAMBER_STREAM.name, CHAMBER_STREAM.names, rows[i:i + 5])
    soak = np.array([[1400.0, 1500.0, 85.0, 84.0, 83.0, 300.0, 5500.0, 1, 1.0]])
    plots.add_samples(WINDOWS.name, WINDOWS.names, soak)
    plots.refresh(force=True)
    x, y = plots.c_temp["air_c"].getData()
    assert x[0] == pytest.approx(0.0) and x[-1] == pytest.approx(599.6)  # the run's time axis, to the last row
    np.testing.assert_allclose(y[[0, -1]], [25.0, 85.0])
    x, y = plots.c_temp["part_c"].getData()
    assert y[-1] == pytest.approx(part[-1])  # the live curve, not the record's mean (83)
    x, y = plots.c_temp["setpoint_c"].getData()
    np.testing.assert_allclose(np.column_stack((x, y)), [[450.0, 85.0]])


def test_force_to_rebalance_output_says_so(plots):
    plots.set_layout("thermal")
    plots.clear()
    plots.set_bryan_factor(0.277)
    assert "K = 0.277" in plots.p_cvg.titleLabel.text
    t = np.arange(0.0, 10.0, 0.1)
    one, z = np.ones_like(t), np.zeros_like(t)
    rows = np.column_stack((t, one, z, z, z, 0.0067 * one, 180.0 + z, 0.04 + z, z))
    plots.add_samples("fpga", ("t_s", "cx", "sx", "cy", "sy", "amp_ctrl", "angle_out_deg", "rate_out_dps",
                               "sat_flags"), rows)
    plots.refresh(force=True)
    assert "force-to-rebalance" in plots.p_cvg.titleLabel.text and "K =" not in plots.p_cvg.titleLabel.text
    np.testing.assert_allclose(plots.c_cvg.getData()[1], 0.04 * 3600.0)


def test_the_temperature_plot_is_offered_for_export_on_a_thermal_run(plots):
    from bench.gui.export import offered_plots

    plots.set_layout("thermal")
    assert "temperature" in offered_plots(plots, None)  # the chamber stream behind it
    plots.set_layout("hrg")
    assert "temperature" not in offered_plots(plots, None)
