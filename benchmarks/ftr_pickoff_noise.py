"""The force-to-rebalance output's pickoff-noise term (docs/noise_model.md): the simulated FPGA's
loops on the World directly (no link), force-to-rebalance at the default gains, white pickoff
noise only (no split, no damping anisotropy, no rate noise); the rate output sampled once a frame
(every second 50 ms block: a 10 Hz stream) and its white level read from the scatter of chunk
means, input-referred, against the closed form of the discrete loop with its one-block delay,
N = |Kp - Ki T / 2| sigma_theta sqrt(T) / K, and the form without the delay, 2 C / (2 - C T).

Run: .venv/bin/python benchmarks/ftr_pickoff_noise.py [sigma] [seconds]   (default 1e-5, 2000)

Measured 2026-11-26 (sigma 1e-5, 2000 s, seed 3), deg/sqrt(h): frames every second block
7.76e-3 (5 s chunks), 7.91e-3 (20 s chunks); closed form with the delay 7.65e-3, without 8.48e-3.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.analysis.slow_model import state_from_elements  # noqa: E402
from drivers.fpga import protocol as p  # noqa: E402
from simulators.fpga import kernels as kk  # noqa: E402
from simulators.fpga.firmware import FpgaFirmware  # noqa: E402
from simulators.physics.params import preset  # noqa: E402
from simulators.world import World  # noqa: E402


class _RateOut:
    """The rate output held over every block (FTR: the rebalance command)."""

    def __init__(self, fw: FpgaFirmware) -> None:
        self.fw, self.u = fw, []

    def before_block(self, *args) -> None:
        pass

    def after_block(self, world, block) -> None:
        self.u.append(float(self.fw._st[kk.S_RATE_OUT]))


def rate_output(sigma: float, seconds: float, seed: int = 3) -> tuple[np.ndarray, float, float]:
    """(rate output per block in deg/s, block period s, K) of a force-to-rebalance run."""
    params = preset("hrg", delta_inv_tau_per_s=0.0, split_hz=0.0, noise_sigma=sigma)
    world = World(params, seed=seed)
    world.resonator.set_state(state_from_elements(1.0, 0.0, 0.0))
    fw = FpgaFirmware(world)
    world.attach(fw)
    for name, value in (("REF_FREQ_HZ", params.f0_hz), ("AGC_SETPOINT", 1.0), ("OUTPUT_MODE", 1)):
        fw.write(p.BY_NAME[name], value)
    fw.write(p.BY_NAME["CTRL"], p.DRIVE_EN | p.AGC_EN | p.PLL_EN | p.QUAD_EN | p.WHOLE_ANGLE)
    world.advance(20.0)
    rec = _RateOut(fw)
    world.attach(rec)
    world.advance(seconds)
    return np.array(rec.u), seconds / len(rec.u), params.bryan_factor


def white_level_dpsh(v_dps: np.ndarray, dt_s: float, chunk: int) -> float:
    """White-noise level (deg/sqrt(h)) of a rate sequence from the scatter of its chunk means."""
    n = len(v_dps) // chunk
    means = v_dps[: n * chunk].reshape(n, chunk).mean(axis=1)
    return float(means.std(ddof=1) * math.sqrt(chunk * dt_s) * 60.0)


def closed_form_dpsh(sigma: float, k: float, t_s: float = 0.05, kp: float = 4.0, ki: float = 4.0,
                     n: int = 50, delay: bool = True) -> float:
    """The aliased pickoff-noise term: |H(-1)| sigma_theta sqrt(T) / K, sigma_theta = sigma / (2 sqrt(n))."""
    c = kp - ki * t_s / 2.0  # the PI at z = -1
    h = abs(c) if delay else abs(2.0 * c / (2.0 - c * t_s))
    return math.degrees(h * sigma / (2.0 * math.sqrt(n)) * math.sqrt(t_s) / k) * 60.0


def main() -> None:
    sigma = float(sys.argv[1]) if len(sys.argv) > 1 else 1e-5
    seconds = float(sys.argv[2]) if len(sys.argv) > 2 else 2000.0
    u, t_s, k = rate_output(sigma, seconds)
    v = u[::2] / k  # a 10 Hz stream frame every second block, input-referred (G = 1)
    for chunk in (50, 200):
        print(f"measured, {chunk * 2 * t_s:.0f} s chunks: {white_level_dpsh(v, 2 * t_s, chunk):.3e} deg/sqrt(h)")
    print(f"closed form with the one-block delay: {closed_form_dpsh(sigma, k, t_s):.3e}; "
          f"without it: {closed_form_dpsh(sigma, k, t_s, delay=False):.3e}")


if __name__ == "__main__":
    main()
