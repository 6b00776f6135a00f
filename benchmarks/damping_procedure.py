"""Benchmark (c): the whole `hrg-damping` procedure on `sim-hrg` (real drivers over loopback,
lockstep clock): simulated seconds per wall second (target >= 100x), and the design check on
the station: runs at the design's recommended table rate against the patent's 500 deg/s.

Run: .venv/bin/python benchmarks/damping_procedure.py [n_seeds]   (default 4 per rate)
"""

from __future__ import annotations

import math
import os
import sys
import tempfile
import time

import numpy as np

from bench.analysis.damping_design import design_hrg_damping
from bench.composition.sim_station import SimStation
from bench.engine import Runner
from procedures.hrg_damping import HrgDamping


def run_once(params: dict, seed: int, runs_dir: str):
    station = SimStation("sim-hrg", seed=seed).open()
    try:
        c0 = time.process_time()
        record = Runner(station, runs_dir=runs_dir).run(HrgDamping, params)
        cpu = time.process_time() - c0
        return record, cpu, station.truth()
    finally:
        station.close()


def main() -> None:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 4
    tmp = tempfile.mkdtemp(prefix="gyrobench-damping-")
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores; raw files in {tmp}")

    rec, cpu, truth = run_once({}, 0, tmp)  # the patent's defaults: 500 deg/s, 900 s record, verify
    print(f"\nfull procedure, defaults: {rec.outcome}, {rec.simulated_s:.0f} s simulated in {rec.wall_s:.1f} s wall "
          f"({rec.simulated_s / rec.wall_s:.0f}x real time; process CPU {cpu:.1f} s)")
    for m in rec.measurements:
        tv = truth.get(m.name)
        ci = "" if m.ci95 is None else f"  ci95 [{m.ci95[0]:.6g}, {m.ci95[1]:.6g}]"
        print(f"  {m.name:22s} {m.value:.6g}{ci}" + ("" if tv is None else f"  truth {tv:.6g}"))

    d = design_hrg_damping(tau_s=truth["tau_s"], delta_inv_tau_per_s=truth["delta_inv_tau_per_s"], noise_sigma=1e-4,
                           stream_hz=1000.0, bryan_factor=truth["bryan_factor"], split_hz=truth["split_hz"],
                           quadrature=0.005, theta_tau_deg=truth["theta_tau_deg"], theta_w_deg=truth["theta_w_deg"],
                           model="exact", lengths_tau=(1.0,))
    print(f"\ndesign (300 s record): recommended {d.recommended.rate_dps:.3g} deg/s, predicted error "
          f"{d.recommended.total_rel:.3%} of D against {d.patent.total_rel:.3%} at 500 deg/s "
          f"({d.gain_vs_patent:.0f}x)")
    b_true = truth["delta_inv_tau_per_s"] * np.array([math.cos(math.radians(4 * truth["theta_tau_deg"])),
                                                      math.sin(math.radians(4 * truth["theta_tau_deg"]))])
    rms = {}
    for rate in (d.recommended.rate_dps, 500.0):
        errs, speed = [], []
        for seed in range(n):
            r, _, _ = run_once({"rate_dps": rate, "record_s": 300.0, "compensate": False}, 100 + seed, tmp)
            m = {x.name: x.value for x in r.measurements}
            th = math.radians(4 * m["theta_tau_deg"])
            b = m["delta_inv_tau_per_s"] * np.array([math.cos(th), math.sin(th)])
            errs.append(b - b_true)
            speed.append(r.simulated_s / r.wall_s)
        errs = np.asarray(errs)
        rms[rate] = math.sqrt(float(np.mean(np.sum(errs**2, axis=1))))
        print(f"  {rate:7.3g} deg/s: rms |b_hat - b| / D = {rms[rate] / truth['delta_inv_tau_per_s']:.3%} over {n} "
              f"seeds, mean error {np.hypot(*errs.mean(axis=0)) / truth['delta_inv_tau_per_s']:+.3%} of D; "
              f"{np.mean(speed):.0f}x real time")
    gain = rms[500.0] / rms[d.recommended.rate_dps]
    print(f"  gain over the patent: predicted {d.gain_vs_patent:.0f}x, measured {gain:.0f}x"
          f" ({n} seeds each: the measured ratio scatters by about {100 / math.sqrt(n):.0f} %)")


if __name__ == "__main__":
    main()
