"""Phase and gain margins of the FPGA's rebalance loop as the firmware samples it, and the PI gains
a stated margin rule gives (docs/chamber.md, "The four rings in one chamber": why a drawn ring was lost).

The loop (simulators/fpga/kernels.py, update_loops and wave_force): once per block of T seconds the
firmware takes the wave angle as the block's mean, updates a PI (u = -(kp e + I), then
I += ki T e) and holds the force F_p = 4 a u over the *next* block; the wave turns at g F_p / (4 a)
(g = 1 for the averaged ring: the plant is an integrator).  In z, with u[n] computed from the mean
angle of block n - 1:
    C(z) = (kp + ki T / (z - 1)) / z,     G(z) = g T (1 + z^-1) / 2 / (1 - z^-1)
(the block mean of an integrator under a held input: half of each of the two blocks' inputs).  The
margins are those of L = C G on the unit circle up to Nyquist; the closed loop's poles are the roots
of its characteristic polynomial, a check independent of the frequency sweep."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Margins:
    """Crossover (rad/s) and phase margin (deg); phase crossover (rad/s) and gain margin (dB)."""

    crossover_rad_s: float
    phase_margin_deg: float
    phase_crossover_rad_s: float
    gain_margin_db: float


def open_loop(w_rad_s: np.ndarray, kp: float, ki: float, period_s: float, plant_gain: float = 1.0) -> np.ndarray:
    """L(e^{jwT}) of the sampled rebalance loop (module docstring)."""
    z = np.exp(1j * np.asarray(w_rad_s, dtype=float) * period_s)
    c = (kp + ki * period_s / (z - 1.0)) / z
    g = plant_gain * period_s * (1.0 + 1.0 / z) / 2.0 / (1.0 - 1.0 / z)
    return c * g


def margins(kp: float, ki: float, period_s: float, plant_gain: float = 1.0, n: int = 200_000) -> Margins:
    """The loop's margins from a sweep up to Nyquist (pi / T)."""
    w = np.linspace(1e-3 / period_s, np.pi / period_s, n)
    loop = open_loop(w, kp, ki, period_s, plant_gain)
    mag, phase = np.abs(loop), np.degrees(np.unwrap(np.angle(loop)))
    i = int(np.argmin(np.abs(np.log(mag))))
    j = int(np.argmin(np.abs(phase + 180.0)))
    return Margins(float(w[i]), float(180.0 + phase[i]), float(w[j]), float(-20.0 * np.log10(mag[j])))


def closed_loop_poles(kp: float, ki: float, period_s: float, plant_gain: float = 1.0) -> np.ndarray:
    """Roots of 1 + L(z) = 0: z (z - 1)^2 2 / (g T) ... cleared of fractions,
    2 z (z - 1)^2 + g T (z + 1)(kp (z - 1) + ki T) = 0 (all inside the unit circle: stable)."""
    g_t = plant_gain * period_s
    lhs = np.polymul([2.0, 0.0], np.polymul([1.0, -1.0], [1.0, -1.0]))
    rhs = g_t * np.polymul([1.0, 1.0], [kp, ki * period_s - kp])
    return np.roots(np.polyadd(lhs, rhs))


def rebalance_gains(period_s: float, *, plant_gain: float = 1.0, phase_margin_deg: float = 45.0,
                    gain_margin_db: float = 6.0, zero_ratio: float = 0.2) -> tuple[float, float, Margins]:
    """The largest kp (with ki = zero_ratio kp^2: the PI's zero a fifth of the gain, below crossover)
    whose loop keeps both margins at the plant gain; (kp, ki, margins).  Searched on a 1 % grid."""
    best = None
    for kp in np.arange(0.5, 2.0 / (plant_gain * period_s), 0.01 / (plant_gain * period_s)):
        ki = zero_ratio * kp * kp
        m = margins(float(kp), float(ki), period_s, plant_gain, n=20_000)
        if m.phase_margin_deg < phase_margin_deg or m.gain_margin_db < gain_margin_db:
            break
        best = (float(kp), float(ki), m)
    if best is None:
        raise ValueError(f"no rebalance gain keeps {phase_margin_deg:g} deg and {gain_margin_db:g} dB at "
                         f"T = {period_s:g} s, plant gain {plant_gain:g}")
    return best
