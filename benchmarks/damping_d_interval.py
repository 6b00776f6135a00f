"""Benchmark: coverage of the Delta(1/tau) interval of hrg-damping's energy fit as D -> 0.

For true D = r standard errors (r = 0 .. 10), seeded noise draws on one decay each (the noise is
additive), the fraction of 95 % intervals holding the truth: the profile-likelihood Neyman belt
(`damping.delta_interval`, today's) and the naive |b| +- 1.96 sd clipped at 0 (before; covers
85 % at D = 0).  Target: inside the 99 % binomial band around 0.95 at every r.
Run: .venv/bin/python benchmarks/damping_d_interval.py [n_draws]   (default 1000)
"""

from __future__ import annotations

import math
import sys
import time

import numpy as np

from bench.analysis import damping as dm
from bench.analysis.damping_design import DecayScenario, energy_bound
from bench.analysis.slow_model import state_from_elements
from simulators.physics.averaged import Resonator
from simulators.physics.params import preset

RATE_DPS, DURATION_S, STREAM_HZ = 100.0, 60.0, 10.0


def main() -> None:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 1000
    half = 2.5758 * math.sqrt(0.95 * 0.05 / n)
    p0 = preset("hrg", split_hz=0.0)
    sc = DecayScenario(tau_s=p0.tau_s, delta_inv_tau_per_s=1e-9, noise_sigma=p0.noise_sigma, rate_dps=RATE_DPS,
                       duration_s=DURATION_S, stream_hz=STREAM_HZ, theta0_deg=math.degrees(0.3))
    sd = energy_bound(sc).std_b_per_s / math.sqrt(2.0)
    print(f"{n} draws per D; sd of b_c, b_s at the bound {sd:.3e} 1/s; target {0.95 - half:.3f}..{0.95 + half:.3f}")
    print("  D/sd   profile-LR belt   naive +-1.96 sd   mean width / (2 x 1.96 sd)")
    t0 = time.perf_counter()
    for r in (0.0, 0.5, 1.0, 1.5, 2.0, 3.0, 5.0, 10.0):
        p = p0.with_(delta_inv_tau_per_s=r * sd)
        res = Resonator(p, seed=0)
        res.set_state(state_from_elements(1.0, 0.0, 0.3, 0.0))
        steps = int(round(DURATION_S * STREAM_HZ))
        q = res.step_block(steps, 1.0 / STREAM_HZ, rate_rad_s=math.radians(RATE_DPS))
        t = np.arange(1, steps + 1) / STREAM_HZ
        rng = np.random.default_rng(2024)
        hit = naive = 0
        widths = []
        for _ in range(n):
            fit = dm.fit_free_decay_q(t, q + rng.normal(0.0, p.noise_sigma, q.shape))
            lo, hi = fit.ci95["delta_inv_tau_per_s"]
            hit += lo <= p.delta_inv_tau_per_s <= hi
            widths.append(hi - lo)
            d, s = fit.delta_inv_tau_per_s, fit.std["delta_inv_tau_per_s"]
            naive += max(0.0, d - 1.96 * s) <= p.delta_inv_tau_per_s <= d + 1.96 * s
        print(f"  {r:4.1f}   {hit / n:15.3f}   {naive / n:15.3f}   {np.mean(widths) / (3.92 * sd):10.2f}")
    print(f"total {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
