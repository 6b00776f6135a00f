"""Benchmark: identification time of the Maslov estimators (target <= 0.5 s).

Forced: 61 steady states of the paper's cubic model (identify, and the modelled response for the
plots).  Free decay: a 300 s record at 1 kHz of the HRG preset spinning at 20 deg/s, batch fits of
the three models and the paper's recursive 4x4-block least squares.  Median of repeats, wall time.
Run: .venv/bin/python benchmarks/maslov_speed.py
"""

from __future__ import annotations

import math
import os
import statistics
import time

import numpy as np

from bench.analysis.maslov import (
    PAPER_CUBIC_PARAMS,
    PAPER_NATURAL_FREQ_HZ,
    identify_forced,
    identify_free_decay,
    recursive_lsq,
    simpson_regressors,
    steady_states,
)
from bench.analysis.maslov_decay import _RLS_CHUNK
from bench.analysis.slow_model import state_from_elements
from simulators.physics.averaged import Resonator
from simulators.physics.params import preset


def timed(fn, repeats: int) -> float:
    """Median wall time; the CPU time of the last run goes to LAST_CPU_S (the machine is shared)."""
    global LAST_CPU_S
    times = []
    for _ in range(repeats):
        c0, t0 = time.process_time(), time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
        LAST_CPU_S = time.process_time() - c0
    return statistics.median(times)


LAST_CPU_S = 0.0


def main() -> None:
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    f0 = PAPER_NATURAL_FREQ_HZ
    freqs = np.linspace(f0 + 1.94 - 12.0, f0 + 1.94 + 12.0, 61)
    z = np.array(list(PAPER_CUBIC_PARAMS.values()))
    t_ss = timed(lambda: steady_states(freqs, z, natural_freq_hz=f0, model="cubic"), 3)
    q = steady_states(freqs, z, natural_freq_hz=f0, model="cubic").q
    q = q + np.random.default_rng(0).normal(0.0, 1.5e-3, q.shape)
    print("forced, 61 steady states (median wall time)")
    for model in ("linear", "cubic", "quintic"):
        dt = timed(lambda m=model: identify_forced(freqs, *q.T, natural_freq_hz=f0, model=m), 20)
        print(f"  identify {model:8s} {1e3 * dt:8.2f} ms")
    print(f"  modelled response (61 nonlinear steady states) {1e3 * t_ss:8.1f} ms")

    p = preset("hrg")
    fs, duration = 1000.0, 300.0
    n = int(duration * fs)
    q0 = state_from_elements(1.0, 0.02, 0.3)
    res = Resonator(p, seed=1, state=q0)
    traj = np.vstack([q0, res.step_block(n, 1.0 / fs, rate_rad_s=math.radians(20.0))])
    qm = res.measure(traj)
    t = np.arange(n + 1) / fs
    print(f"free decay, {duration:.0f} s at {fs:.0f} Hz ({n + 1} samples)")
    for model in ("linear", "cubic", "quintic"):
        dt = timed(lambda m=model: identify_free_decay(t, *qm.T, model=m), 3)
        flag = "ok" if dt <= 0.5 else "over 0.5 s target"
        print(f"  batch {model:8s} {dt:8.3f} s wall, {LAST_CPU_S:6.3f} s CPU  {flag}")
    for model in ("linear", "cubic", "quintic"):
        dt = timed(lambda m=model: identify_free_decay(t, *qm.T, model=m, recursive=True), 3)
        print(f"  recursive {model:8s} {dt:8.3f} s wall ({1e6 * dt / n:.2f} us/block; eq. 2.12 in chunks of "
              f"{_RLS_CHUNK} 4x4 blocks, push-through update)")
    x, y = simpson_regressors(qm, 1.0 / fs, "linear")
    t0 = time.perf_counter()
    recursive_lsq(x[:30000], y[:30000], 600)
    dt = time.perf_counter() - t0
    print(f"  literal one-4x4-block loop (recursive_lsq chunk_blocks=1), 30000 blocks {dt:.2f} s = "
          f"{1e6 * dt / 29400:.1f} us/block")

if __name__ == "__main__":
    main()
