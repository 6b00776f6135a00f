"""Benchmark (a): scatter of the damping estimates against the Cramer-Rao bounds.

For each parameter set, 100+ seeded decays from the simulator's resonator (the trajectory is
deterministic, each seed draws the pickoff noise exactly as `Resonator.measure` does in the
World), fitted by the weighted log-linear fit and the patent's Gauss-Newton.  Prints std/CRLB
(energy bound, the target <= 1.15), bias in sigma (target < 0.2), 95 % interval coverage
(target 0.93-0.97) and the four-channel bound.  Then the design check: the recommended rate
against the patent's 500 deg/s, predicted and measured.
Run: .venv/bin/python benchmarks/damping_accuracy.py [n_seeds]
"""

from __future__ import annotations

import math
import sys
import time

import numpy as np

from bench.analysis import damping as dm
from bench.analysis.damping_design import DecayScenario, design_hrg_damping, energy_bound, four_channel_bound
from bench.analysis.slow_model import state_from_elements
from simulators.physics.averaged import Resonator
from simulators.physics.params import preset

THETA0_RAD = 0.3


def true_decay(params, rate_dps, duration_s, stream_hz, k0, ripple_deg=0.0, ripple_hz=0.0):
    res = Resonator(params, seed=0)
    res.set_state(state_from_elements(1.0, k0, THETA0_RAD, 0.0))
    n = int(round(duration_s * stream_hz))
    t = np.arange(1, n + 1) / stream_hz
    ripple = None
    if ripple_deg:
        ripple = np.radians(ripple_deg) * np.sin(2 * math.pi * ripple_hz * t)
    q = res.step_block(n, 1.0 / stream_hz, rate_rad_s=math.radians(rate_dps), ripple_angle_rad=ripple)
    return t, q


def scenario(params, rate_dps, duration_s, stream_hz, k0):
    return DecayScenario(
        tau_s=params.tau_s, delta_inv_tau_per_s=params.delta_inv_tau_per_s, noise_sigma=params.noise_sigma,
        rate_dps=rate_dps, duration_s=duration_s, stream_hz=stream_hz, theta_tau_deg=params.theta_tau_deg,
        theta0_deg=math.degrees(THETA0_RAD), quadrature=k0, split_hz=params.split_hz,
        theta_w_deg=params.theta_w_deg, bryan_factor=params.bryan_factor,
    )


def run_set(label, params, rate_dps, duration_s, stream_hz, k0, n_seeds, methods, model="exact", **ripple):
    t, q = true_decay(params, rate_dps, duration_s, stream_hz, k0, **ripple)
    sc = scenario(params, rate_dps, duration_s, stream_hz, k0)
    eb, fb = energy_bound(sc), four_channel_bound(sc)
    truth = params.truth()
    print(f"\n{label}: {rate_dps:g} deg/s, {duration_s:g} s at {stream_hz:g} Hz, tau {params.tau_s:g} s, "
          f"D {params.delta_inv_tau_per_s:.3g}, split {params.split_hz:g} Hz, k0 {k0:g}, "
          f"noise {params.noise_sigma:g}, model {model}{', ripple ' + str(ripple) if ripple else ''}")
    rel = eb.std_delta_inv_tau_per_s / truth["delta_inv_tau_per_s"]
    print(f"  energy CRLB: std D {eb.std_delta_inv_tau_per_s:.3e} ({rel:.2%} of D), "
          f"th_tau {eb.std_theta_tau_deg:.3e} deg, tau {eb.std_tau_s:.3e} s;  four-channel: std D "
          f"{fb.std_delta_inv_tau_per_s:.3e}, th_tau {fb.std_theta_tau_deg:.3e} deg "
          f"(energy/four-channel {eb.std_delta_inv_tau_per_s / fb.std_delta_inv_tau_per_s:.2f}x)")
    bound = {"delta_inv_tau_per_s": eb.std_delta_inv_tau_per_s, "theta_tau_deg": eb.std_theta_tau_deg,
             "tau_s": eb.std_tau_s}
    for method in methods:
        est = {k: [] for k in dm.CI_NAMES}
        cover = {k: 0 for k in dm.CI_NAMES}
        t0 = time.perf_counter()
        for seed in range(n_seeds):
            qm = Resonator(params, seed=1000 + seed).measure(q)
            fit = dm.fit_free_decay(t, *qm.T, method=method, model=model)
            for k in dm.CI_NAMES:
                est[k].append(getattr(fit, k))
                lo, hi = fit.ci95[k]
                cover[k] += lo <= truth[k] <= hi
        wall = time.perf_counter() - t0
        for k in dm.CI_NAMES:
            v = np.asarray(est[k])
            sd = v.std(ddof=1)
            print(f"  {method:24s} {k:20s} std/CRLB {sd / bound[k]:5.3f}  bias {(v.mean() - truth[k]) / sd:+6.3f} sigma"
                  f"  coverage {cover[k] / n_seeds:.3f}")
        print(f"  {method:24s} ({n_seeds} fits in {wall:.1f} s)")


def design_check(n_seeds):
    """The design's recommended rate against the patent's 500 deg/s on the HRG preset."""
    p = preset("hrg")
    k0, duration, fs = 0.01, 300.0, 200.0
    d = design_hrg_damping(tau_s=p.tau_s, delta_inv_tau_per_s=p.delta_inv_tau_per_s, noise_sigma=p.noise_sigma,
                           stream_hz=fs, bryan_factor=p.bryan_factor, split_hz=p.split_hz, quadrature=k0,
                           theta_tau_deg=p.theta_tau_deg, theta_w_deg=p.theta_w_deg, model="exact",
                           lengths_tau=(duration / p.tau_s,))
    print("\n" + d.summary())
    rms = {}
    for rate in (d.recommended.rate_dps, d.patent.rate_dps):
        t, q = true_decay(p, rate, duration, fs, k0)
        err = []
        for seed in range(n_seeds):
            qm = Resonator(p, seed=5000 + seed).measure(q)
            fit = dm.fit_free_decay(t, *qm.T)
            err.append((fit.b_c_per_s - p.coefficients().b_c, fit.b_s_per_s - p.coefficients().b_s))
        err = np.asarray(err)
        rms[rate] = math.sqrt(float(np.mean(np.sum(err**2, axis=1))))
        mean_bias = np.hypot(*err.mean(axis=0)) / (rms[rate] / math.sqrt(2))
        print(f"  measured at {rate:.3g} deg/s: rms |b_hat - b| / D = {rms[rate] / p.delta_inv_tau_per_s:.3%}, "
              f"mean offset {mean_bias:.2f} sigma ({n_seeds} seeds)")
    measured = rms[d.patent.rate_dps] / rms[d.recommended.rate_dps]
    print(f"  gain over the patent: predicted {d.gain_vs_patent:.1f}x, measured {measured:.1f}x")


def coverage_check(n_draws: int) -> None:
    """Interval coverage with many draws (binomial sd 0.7 % at 1000), on one shared trajectory."""
    hrg = preset("hrg")
    sets = {
        "A' 500 deg/s, 200 Hz": (hrg, 500.0, 300.0, 200.0, 0.0),
        "B split + quadrature": (hrg.with_(split_hz=0.05 / (2 * math.pi), delta_inv_tau_per_s=2e-4), 20.0, 300.0,
                                 200.0, 0.02),
    }
    print(f"\n95 % interval coverage over {n_draws} noise draws (target 0.93-0.97):")
    for label, (p, rate, dur, fs, k0) in sets.items():
        t, q = true_decay(p, rate, dur, fs, k0)
        truth = p.truth()
        cover = {k: 0 for k in dm.CI_NAMES}
        for seed in range(n_draws):
            fit = dm.fit_free_decay(t, *Resonator(p, seed=7000 + seed).measure(q).T)
            for k in dm.CI_NAMES:
                lo, hi = fit.ci95[k]
                cover[k] += lo <= truth[k] <= hi
        print(f"  {label:24s} " + "  ".join(f"{k} {cover[k] / n_draws:.3f}" for k in dm.CI_NAMES))


def main() -> None:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 100
    hrg = preset("hrg")
    t_all = time.perf_counter()
    both = ("log-linear", "gauss-newton")
    run_set("A patent conditions", hrg, 500.0, 300.0, 1000.0, 0.0, n, both)
    run_set("B split + quadrature", hrg.with_(split_hz=0.05 / (2 * math.pi), delta_inv_tau_per_s=2e-4), 20.0, 300.0,
            200.0, 0.02, n, ("log-linear",))
    run_set("B' same, patent model", hrg.with_(split_hz=0.05 / (2 * math.pi), delta_inv_tau_per_s=2e-4), 20.0, 300.0,
            200.0, 0.02, n, ("log-linear",), model="patent")
    run_set("C long tau, small D", hrg.with_(tau_s=600.0, delta_inv_tau_per_s=4e-5, theta_tau_deg=71.0), 100.0,
            900.0, 100.0, 0.005, n, both)
    run_set("D table-rate ripple", hrg, 100.0, 300.0, 200.0, 0.0, n, ("log-linear",), ripple_deg=0.05,
            ripple_hz=3.0)
    design_check(n)
    coverage_check(10 * n)
    print(f"\ntotal {time.perf_counter() - t_all:.0f} s")


if __name__ == "__main__":
    main()
