"""The frequency the FPGA's loops run the MEMS ring at (#34, #31 item 8): the thermal procedures'
f0_at_25c_hz is the PLL's frequency, which on the ring sits 2.41 Hz under f0 + freq_offset (the
small-amplitude mean of its two modes): the held wave's own mode (-1.02 Hz of the 2.75 Hz split),
the cubic stiffness at the AGC's amplitude (-1.09 Hz) and the readout's 5 deg phase delay
(-0.31 Hz).  The truth states that frequency (drive_freq_offset_hz, docs/chamber.md, "The frequency
the loops run at")."""

from __future__ import annotations

import math

import numpy as np
import pytest

from simulators.physics.drive_frequency import drive_frequency_offset_hz, true_amplitude
from simulators.physics.errors import ERROR_PRESETS, ErrorSources
from simulators.physics.params import PRESETS


def test_each_term_of_the_drive_frequency_by_hand():
    """The three terms, each alone, against the averaged model's coefficients written out."""
    ring = PRESETS["mems-realistic"]
    c = ring.coefficients()
    split_hz = c.h_c / 2.0 / (2.0 * math.pi)  # the wave held at 0 deg: the x mode's own offset
    assert drive_frequency_offset_hz(ring.with_(xi_per_s=0.0), None, setpoint=1.0, angle_deg=0.0) == \
        pytest.approx(split_hz, rel=1e-12)
    assert split_hz == pytest.approx(-1.018, abs=1e-3)
    cubic_hz = -3.0 * c.xi * 0.25 / 8.0 / (2.0 * math.pi)  # at a = 0.5: -3 xi a^2 / 8
    assert drive_frequency_offset_hz(ring.with_(split_hz=0.0), None, setpoint=0.5, angle_deg=0.0) == \
        pytest.approx(cubic_hz, rel=1e-12)
    phase = ErrorSources(pickoff_phase_x_deg=5.0, pickoff_phase_y_deg=9.0)
    flat = ring.with_(split_hz=0.0, xi_per_s=0.0)
    gamma_x = c.gamma + c.b_c
    assert drive_frequency_offset_hz(flat, phase, setpoint=1.0, angle_deg=0.0) == \
        pytest.approx(-0.5 * gamma_x * math.tan(math.radians(5.0)) / (2.0 * math.pi), rel=1e-12)
    # a phase trim takes its share back; at 45 deg the wave lies on the y chain
    assert drive_frequency_offset_hz(flat, phase, setpoint=1.0, angle_deg=0.0, trim_phase_x_deg=5.0) == 0.0
    gamma_y = c.gamma - c.b_c
    assert drive_frequency_offset_hz(flat, phase, setpoint=1.0, angle_deg=45.0) == \
        pytest.approx(-0.5 * gamma_y * math.tan(math.radians(9.0)) / (2.0 * math.pi), rel=1e-9)
    # the AGC holds the reading: a chain that reads high holds a smaller wave
    e = ErrorSources(pickoff_gain_cm_ppm=2000.0, pickoff_cubic=5e-3)
    a = true_amplitude(1.0, 0.0, e)
    assert 1.002 * a * (1.0 + 0.75 * 5e-3 * a * a) == pytest.approx(1.0, rel=1e-12)
    assert drive_frequency_offset_hz(ring, ERROR_PRESETS["mems-realistic"], setpoint=1.0, angle_deg=0.0) == \
        pytest.approx(-2.41, abs=0.01)


def test_the_rings_pll_runs_at_the_stated_truth():
    """sim-mems-thermal (seed 0) at 25 degC, its loops as the thermal procedures set them (AGC at
    1.0, PLL, quadrature loop, force-to-rebalance at 0 deg): after 40 s the PLL's mean frequency over
    10 s is the f0_at_25c_hz truth within 0.02 Hz (1.5 ppm; the soak's interval is a few times that),
    and 2.41 Hz under the small-amplitude mean f0 + freq_offset the truth stated before."""
    from bench.composition import load_station
    from procedures.thermal_soak import ThermalSoak

    station = load_station("sim-mems-thermal", seed=0).open()
    try:
        fpga = station.devices["fpga"]
        fpga.set_whole_angle(False)
        fpga.set_pll(True)
        fpga.set_quadrature_loop(True)
        fpga.set_agc(True, 1.0)
        fpga.set_drive_enabled(True)
        station.clock.sleep(40.0)
        freqs = []
        for _ in range(20):
            station.clock.sleep(0.5)
            freqs.append(float(fpga.read_register("PLL_FREQ_HZ")))
        truth = station.truth()
    finally:
        station.close()
    f_pll = float(np.mean(freqs))
    small_amplitude_mean = truth["f0_hz"] + truth["freq_offset_hz"]
    assert truth["drive_freq_offset_hz"] == pytest.approx(-2.41, abs=0.01)
    assert f_pll - small_amplitude_mean == pytest.approx(-2.41, abs=0.02)
    assert ThermalSoak.truth_for(truth)["f0_at_25c_hz"] == pytest.approx(f_pll, abs=0.02)
