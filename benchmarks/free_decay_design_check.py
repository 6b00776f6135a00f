"""Benchmark: does `gyrobench design hrg-free-decay` predict what the procedure achieves?

Designs hrg-free-decay for the sim-hrg preset exactly as the CLI does (the procedure's 100 Hz
stream, boxcar from the 1 kHz FPGA samples, records of 0.5 or 1 tau here to keep the run short),
then runs the procedure with the recommended table rate and record length on sim-hrg over
`n_seeds` station seeds and compares the scatter of D, theta_tau and tau with the predicted CRLB
(target: within 20 %; with 20 seeds the std of a std is 16 %), and the coverage of their intervals.
Run: .venv/bin/python benchmarks/free_decay_design_check.py [n_seeds]   (default 20)
"""

from __future__ import annotations

import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from bench.analysis.damping_design import design_hrg_free_decay
from bench.engine import Runner
from bench.station import SimStation
from procedures.hrg_free_decay import HrgFreeDecay
from simulators.physics.params import preset

SAMPLE_HZ = 1000.0  # the simulated FPGA's sample rate (station sample_period_s = 1 ms)


def main() -> None:
    n_seeds = int(sys.argv[1]) if len(sys.argv) > 1 else 20
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
    cover = dict.fromkeys(names, 0)
    truth = None
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(n_seeds):
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
                cover[k] += m[k].ci95[0] <= truth[k] <= m[k].ci95[1]
            print(f"  seed {seed}: D {m['delta_inv_tau_per_s'].value:.6e}  th_tau {m['theta_tau_deg'].value:.4f}  "
                  f"tau {m['tau_s'].value:.4f}  ({time.perf_counter() - t0:.0f} s)", flush=True)
    n = len(vals["tau_s"])
    print(f"\n{n} runs at {rec.rate_dps:.4g} deg/s, {rec.duration_s:.0f} s, {stream_hz:g} Hz:")
    print("  quantity               predicted std   measured std   ratio   rms about truth   coverage")
    for k, pred in names.items():
        v = np.asarray(vals[k])
        sd = v.std(ddof=1)
        rms = math.sqrt(float(np.mean((v - truth[k]) ** 2)))
        print(f"  {k:22s} {pred:13.4e}   {sd:12.4e}   {sd / pred:5.2f}   {rms:15.4e}   {cover[k] / n:.2f}")
    print(f"total {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
