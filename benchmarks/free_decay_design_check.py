"""Benchmark: does `gyrobench design hrg-free-decay` predict what the procedure achieves?

Designs hrg-free-decay for the sim-hrg preset exactly as the CLI does (the procedure's 100 Hz
stream, boxcar from the 1 kHz FPGA samples, records of 0.5 or 1 tau here to keep the run short),
then runs the procedure with the recommended table rate and record length on sim-hrg over
`n_seeds` station seeds and compares the scatter of D, theta_tau and tau with the predicted CRLB
(target: within 20 %), with the 90 % interval of the true ratio from the chi-square law of a
sample variance (with 20 seeds the std of a std is 16 %: 0.73-1.26 around a true 1), the mean
of the fits' own standard errors (half the 95 % interval / 1.96) over the prediction (a check of
the design's noise, amplitude and trajectory that is not limited by the number of seeds), and
the coverage of their intervals.
Run: .venv/bin/python benchmarks/free_decay_design_check.py [n_seeds] [first_seed]   (default 20, 0)
"""

from __future__ import annotations

import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.stats import chi2

from bench.analysis.damping_design import design_hrg_free_decay
from bench.composition.sim_station import SimStation
from bench.engine import Runner
from procedures.hrg_free_decay import HrgFreeDecay
from simulators.physics.params import preset

Z_NAMES = ("gamma", "b_c", "b_s", "h_c", "h_s")
SAMPLE_HZ = 1000.0  # the simulated FPGA's sample rate (station sample_period_s = 1 ms)


def main() -> None:
    n_seeds = int(sys.argv[1]) if len(sys.argv) > 1 else 20
    seed0 = int(sys.argv[2]) if len(sys.argv) > 2 else 0
    p = preset("hrg")
    stream_hz = float(HrgFreeDecay.stream_hz.default)
    design = design_hrg_free_decay(
        tau_s=p.tau_s, delta_inv_tau_per_s=p.delta_inv_tau_per_s,
        noise_sigma=p.noise_sigma * math.sqrt(stream_hz / SAMPLE_HZ), stream_hz=stream_hz,
        bryan_factor=p.bryan_factor, split_hz=p.split_hz, theta_tau_deg=p.theta_tau_deg, theta_w_deg=p.theta_w_deg,
        lengths_tau=(0.5, 1.0),
    )
    print(design.summary())
    rec = design.recommended
    names = {"delta_inv_tau_per_s": rec.std_delta_inv_tau_per_s, "theta_tau_deg": rec.std_theta_tau_deg,
             "tau_s": rec.std_tau_s}
    vals: dict[str, list[float]] = {k: [] for k in names}
    ses: dict[str, list[float]] = {k: [] for k in names}
    cover = dict.fromkeys(names, 0)
    zs: dict[str, list[float]] = {k: [] for k in Z_NAMES}
    truth = None
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(seed0, seed0 + n_seeds):
            station = SimStation("sim-hrg", seed=seed).open()
            try:
                record = Runner(station, runs_dir=Path(tmp) / "runs").run(
                    HrgFreeDecay, {"record_s": rec.duration_s, "rate_dps": rec.rate_dps})
                truth = station.truth()
            finally:
                station.close()
            if record.outcome != "COMPLETE":
                print(f"seed {seed}: {record.outcome}")
                continue
            m = {r.name: r for r in record.measurements}
            for k in names:
                vals[k].append(m[k].value)
                ses[k].append((m[k].ci95[1] - m[k].ci95[0]) / (2.0 * 1.959964))
                cover[k] += m[k].ci95[0] <= truth[k] <= m[k].ci95[1]
            for k in Z_NAMES:  # (estimate - truth) / standard error of the coefficients the fit reports
                lo_k, hi_k = m["maslov_" + k].ci95
                zs[k].append((m["maslov_" + k].value - truth[k]) / ((hi_k - lo_k) / (2.0 * 1.959964)))
            print(f"  seed {seed}: D {m['delta_inv_tau_per_s'].value:.6e}  th_tau {m['theta_tau_deg'].value:.4f}  "
                  f"tau {m['tau_s'].value:.4f}  z " + " ".join(f"{k} {zs[k][-1]:+.2f}" for k in Z_NAMES)
                  + f"  ({time.perf_counter() - t0:.0f} s)", flush=True)
    n = len(vals["tau_s"])
    print(f"\n{n} runs at {rec.rate_dps:.4g} deg/s, {rec.duration_s:.0f} s, {stream_hz:g} Hz:")
    lo, hi = (math.sqrt(chi2.ppf(a, n - 1) / (n - 1)) for a in (0.95, 0.05))
    print("  quantity               predicted std   measured std   ratio (90 % interval)   own se / pred"
          "   rms about truth   coverage")
    for k, pred in names.items():
        v = np.asarray(vals[k])
        sd = v.std(ddof=1)
        rms = math.sqrt(float(np.mean((v - truth[k]) ** 2)))
        r = sd / pred
        print(f"  {k:22s} {pred:13.4e}   {sd:12.4e}   {r:5.2f} ({r / lo:4.2f}-{r / hi:4.2f})   "
              f"{np.mean(ses[k]) / pred:13.2f}   {rms:15.4e}   {cover[k] / n:.2f}")
    print("  coefficient z = (estimate - truth) / se: std (1 if the intervals are right), largest |z|")
    for k in Z_NAMES:
        z = np.asarray(zs[k])
        print(f"  {k:6s} std {z.std(ddof=1):5.2f}  mean {z.mean():+5.2f}  max |z| {np.max(np.abs(z)):4.2f} "
              f"(seed {seed0 + int(np.argmax(np.abs(z)))})")
    print(f"total {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
