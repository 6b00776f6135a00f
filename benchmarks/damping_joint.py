"""Benchmark (a, joint part): the four-channel output-error fit against the four-channel bound,
with and without table-rate ripple (which turns the wave outside the model), next to the energy fit.

Run: .venv/bin/python benchmarks/damping_joint.py [n_seeds]   (default 30 per case)
"""

from __future__ import annotations

import sys
import time

import numpy as np

from bench.analysis.damping import fit_free_decay
from bench.analysis.damping_design import energy_bound, four_channel_bound
from bench.analysis.damping_joint import fit_joint_decay
from simulators.physics.averaged import Resonator
from simulators.physics.params import preset

sys.path.insert(0, __file__.rsplit("/", 1)[0])
from damping_accuracy import scenario, true_decay  # noqa: E402


def main() -> None:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 30
    p = preset("hrg")
    rate, dur, fs = 100.0, 300.0, 200.0
    sc = scenario(p, rate, dur, fs, 0.0)
    fb, eb = four_channel_bound(sc), energy_bound(sc)
    d = p.delta_inv_tau_per_s
    print(f"HRG preset, {rate:g} deg/s, {dur:g} s at {fs:g} Hz; bounds on std D: four-channel "
          f"{fb.std_delta_inv_tau_per_s:.3e} ({fb.std_delta_inv_tau_per_s / d:.2%} of D), "
          f"energy {eb.std_delta_inv_tau_per_s:.3e} "
          f"({eb.std_delta_inv_tau_per_s / d:.2%})")
    for label, ripple in (("no ripple", {}), ("ripple 0.01 deg at 3 Hz", {"ripple_deg": 0.01, "ripple_hz": 3.0}),
                          ("ripple 0.05 deg at 3 Hz", {"ripple_deg": 0.05, "ripple_hz": 3.0})):
        t, q = true_decay(p, rate, dur, fs, 0.0, **ripple)
        joint, energy, noise = [], [], []
        t0 = time.perf_counter()
        for seed in range(n):
            qm = Resonator(p, seed=3000 + seed).measure(q)
            f = fit_joint_decay(t, *qm.T, bin_samples=10)
            joint.append((f.delta_inv_tau_per_s, f.theta_tau_deg))
            noise.append(f.noise_sigma)
            e = fit_free_decay(t, *qm.T)
            energy.append((e.delta_inv_tau_per_s, e.theta_tau_deg))
        wall = time.perf_counter() - t0
        joint, energy = np.asarray(joint), np.asarray(energy)
        print(f"\n{label} ({n} seeds, {wall:.0f} s):")
        for name, arr, bound in (("joint ", joint, fb), ("energy", energy, eb)):
            sd = arr[:, 0].std(ddof=1)
            print(f"  {name} std D / its bound {sd / bound.std_delta_inv_tau_per_s:5.2f}, std D / four-channel bound "
                  f"{sd / fb.std_delta_inv_tau_per_s:5.2f}, bias D {(arr[:, 0].mean() - d) / sd:+.2f} sigma, "
                  f"std th_tau / bound {arr[:, 1].std(ddof=1) / bound.std_theta_tau_deg:5.2f}")
        print(f"  joint fit's residual noise estimate {np.mean(noise):.3g} (true {p.noise_sigma:g})")


if __name__ == "__main__":
    main()
