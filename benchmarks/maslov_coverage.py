"""Benchmark: Monte-Carlo coverage of the Maslov estimators' 95 % intervals (target 0.93-0.97).

Forced: the paper's cubic model, 61 steady states, white noise 1.0e-3 per slow variable (the size
that gives the paper's residual sigma ~0.09).  Free decay: the HRG preset spinning at 20 deg/s,
300 s records at 10 Hz and 100 Hz.  For each: coverage per parameter of the corrected interval
(`ci95`, sandwich) and of the paper's textbook interval (`ci95_textbook`, eq. 2.11), and the
ratio of the textbook half-width to the Monte-Carlo scatter.
Run: .venv/bin/python benchmarks/maslov_coverage.py [n_seeds]   (default 200)
"""

from __future__ import annotations

import math
import sys
import time

import numpy as np

from bench.analysis.maslov import (
    PAPER_CUBIC_PARAMS,
    PAPER_NATURAL_FREQ_HZ,
    identify_forced,
    identify_free_decay,
    steady_states,
)
from bench.analysis.slow_model import LINEAR_PARAM_NAMES, state_from_elements
from simulators.physics.averaged import Resonator
from simulators.physics.params import preset


def summarise(title: str, truth: dict[str, float], results: list) -> None:
    names = list(truth)
    n = len(results)
    print(f"{title}  ({n} seeds)")
    print(f"  {'param':8s} {'cover':>6s} {'textbk':>6s} {'bias/sd':>8s} {'sd/se':>6s} {'text_hw/(1.96 sd)':>18s}")
    all_cover = []
    for name in names:
        est = np.array([r.params[name] for r in results])
        cover = np.mean([r.ci95[name][0] <= truth[name] <= r.ci95[name][1] for r in results])
        text = np.mean([r.ci95_textbook[name][0] <= truth[name] <= r.ci95_textbook[name][1] for r in results])
        sd = est.std(ddof=1)
        se = np.median([r.sigma_params[name] for r in results])
        hw_text = np.median([0.5 * (r.ci95_textbook[name][1] - r.ci95_textbook[name][0]) for r in results])
        bias = (est.mean() - truth[name]) / sd if sd > 0 else 0.0
        all_cover.append(cover)
        print(f"  {name:8s} {cover:6.3f} {text:6.3f} {bias:8.2f} {sd / se:6.2f} {hw_text / (1.96 * sd):18.2f}")
    band = 1.96 * math.sqrt(0.95 * 0.05 / n)
    print(f"  corrected coverage range {min(all_cover):.3f}..{max(all_cover):.3f} (binomial 95 % band for a true "
          f"0.95: {0.95 - band:.3f}..{0.95 + band:.3f})")


def forced(n_seeds: int) -> None:
    f0 = PAPER_NATURAL_FREQ_HZ
    freqs = np.linspace(f0 + 1.94 - 12.0, f0 + 1.94 + 12.0, 61)
    z = np.array(list(PAPER_CUBIC_PARAMS.values()))
    clean = steady_states(freqs, z, natural_freq_hz=f0, model="cubic").q
    rng = np.random.default_rng(12345)
    t0 = time.perf_counter()
    results = []
    for _ in range(n_seeds):
        noisy = clean + rng.normal(0.0, 1.0e-3, clean.shape)
        results.append(identify_forced(freqs, *noisy.T, natural_freq_hz=f0, model="cubic"))
    print(f"  sigma median {np.median([r.sigma for r in results]):.4f} (paper 0.0926); "
          f"{time.perf_counter() - t0:.1f} s")
    summarise("forced, cubic, 61 points, noise 1.0e-3", dict(PAPER_CUBIC_PARAMS), results)


def free_decay(n_seeds: int, fs_hz: float, duration_s: float) -> None:
    p = preset("hrg")
    rate = math.radians(20.0)
    truth = dict(zip(LINEAR_PARAM_NAMES, p.coefficients().zg(rate), strict=True))
    q0 = state_from_elements(1.0, 0.02, math.radians(17.0))
    n = int(round(duration_s * fs_hz))
    clean = np.vstack([q0, Resonator(p, seed=0, state=q0).step_block(n, 1.0 / fs_hz, rate_rad_s=rate)])
    t = np.arange(n + 1) / fs_hz
    t0 = time.perf_counter()
    results = []
    for seed in range(n_seeds):
        noisy = Resonator(p, seed=1000 + seed).measure(clean)
        results.append(identify_free_decay(t, *noisy.T, model="linear"))
    print(f"  {time.perf_counter() - t0:.1f} s")
    summarise(f"free decay, HRG at 20 deg/s, {duration_s:.0f} s at {fs_hz:.0f} Hz, linear", truth, results)


def main() -> None:
    n_seeds = int(sys.argv[1]) if len(sys.argv) > 1 else 200
    forced(n_seeds)
    free_decay(n_seeds, 10.0, 300.0)
    free_decay(n_seeds, 100.0, 300.0)


if __name__ == "__main__":
    main()
