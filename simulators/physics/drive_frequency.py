"""The frequency a drive loop runs a standing wave at, against the resonator's mean natural frequency.

A PLL that holds the measured phase of a wave held at angle theta (force-to-rebalance) with its
amplitude held by an AGC does not run at f0 + freq_offset (the small-amplitude mean of the two
modes, the World's `f0_hz` + `freq_offset_hz`), but at that plus three terms of the averaged model
(PHYSICS.md section 2; docs/chamber.md, "The frequency the loops run at"):
  * the split along the wave: (h_c cos 4 theta + h_s sin 4 theta) / 2, the held wave's own mode;
  * the cubic stiffness at the wave's true amplitude a: -3 xi a^2 / 8 (k_cubic's e = 3 a^2 / 4);
  * the readout's phase delay phi (less any phase trim): the AGC's force, laid along the wave as the
    pickoffs read it, leans phi off the true wave, and the wave's phase stays put only if its detuning
    takes the lean's quadrature part: -(gamma_theta / 2) tan phi, gamma_theta = gamma + b_c cos 4 theta
    + b_s sin 4 theta the held wave's damping.
All in rad/s here; the result is in Hz.
"""

from __future__ import annotations

import math

from .errors import REFERENCE_TEMPERATURE_C, ErrorSources
from .params import TWO_PI, ResonatorParams


def true_amplitude(setpoint: float, angle_deg: float, errors: ErrorSources | None,
                   temperature_c: float = REFERENCE_TEMPERATURE_C) -> float:
    """The wave's true amplitude when the AGC holds the pickoffs' reading at `setpoint`: the
    reading is g a (1 + (3/4) e3 a^2) along the wave (gain and cubic of the chains, weighted by the
    wave's share on each), solved by fixed-point iteration."""
    if errors is None:
        return float(setpoint)
    w_x = math.cos(2.0 * math.radians(angle_deg)) ** 2
    gx, gy = errors.pickoff_gains(0.0, temperature_c)
    g = w_x * gx + (1.0 - w_x) * gy
    a = float(setpoint)
    for _ in range(20):
        a = setpoint / (g * (1.0 + 0.75 * errors.pickoff_cubic * a * a))
    return a


def drive_frequency_offset_hz(params: ResonatorParams, errors: ErrorSources | None, *, setpoint: float,
                              angle_deg: float, trim_phase_x_deg: float = 0.0,
                              trim_phase_y_deg: float = 0.0) -> float:
    """The drive loop's frequency minus f0_hz + freq_offset_hz (Hz), at the reference temperature:
    split along the held wave, cubic stiffness at its true amplitude, the readout phase's detuning."""
    c = params.coefficients()
    th4 = 4.0 * math.radians(angle_deg)
    split = 0.5 * (c.h_c * math.cos(th4) + c.h_s * math.sin(th4))
    a = true_amplitude(setpoint, angle_deg, errors)
    cubic = -3.0 * c.xi * a * a / 8.0
    phase = 0.0
    if errors is not None:
        w_x = math.cos(2.0 * math.radians(angle_deg)) ** 2
        phi_deg = (w_x * (errors.pickoff_phase_x_deg - trim_phase_x_deg)
                   + (1.0 - w_x) * (errors.pickoff_phase_y_deg - trim_phase_y_deg))
        gamma_theta = c.gamma + c.b_c * math.cos(th4) + c.b_s * math.sin(th4)
        phase = -0.5 * gamma_theta * math.tan(math.radians(phi_deg))
    return (split + cubic + phase) / TWO_PI
