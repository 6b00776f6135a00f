"""Benchmark: free-decay identification against the Cramer-Rao bound (issue 21).

Three resonators (each with a frequency split, a mistuning c_m and a quadrature at the cut),
300 s records at 10 Hz and 100 Hz streams, linear and cubic models.  For each case, over seeded
noise draws on one noise-free trajectory (the noise is additive): per parameter the scatter over
the CRLB (`crlb_free_decay`) and the mean offset in CRLB units, for the equation-error fit (the
paper's) and the output-error fit (target std/CRLB <= 1.2), and the coverage of the 95 %
intervals (target: inside the 99 % binomial band around 0.95 for the number of seeds).  Then the
fit time of 300 s at 100 Hz (target < 1 s for the linear model).  Serial (one process).
Run: .venv/bin/python benchmarks/free_decay_crlb.py [--seeds N] [--cubic-seeds N] [--case TEXT] [--seed0 K]
(default 200 seeds from noise seed 10000, all cases; --case keeps the cases whose label, e.g.
"hrg-long-tau 10 Hz cubic", contains TEXT, to split a run into pieces of a few minutes)
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from bench.analysis.damping_design import crlb_free_decay
from bench.analysis.maslov import identify_free_decay
from bench.analysis.maslov_terms import free_param_names
from bench.analysis.slow_model import state_from_elements
from simulators.physics.averaged import Resonator
from simulators.physics.params import preset

DURATION_S = 300.0
#: name: (resonator, table rate deg/s, quadrature at the cut, wave angle at the cut deg)
RESONATORS = {
    "hrg": (preset("hrg", freq_offset_hz=0.002), 20.0, 0.02, 17.0),
    "hrg-long-tau": (preset("hrg", tau_s=600.0, delta_inv_tau_per_s=4e-5, theta_tau_deg=71.0, split_hz=0.02,
                            theta_w_deg=33.0, freq_offset_hz=-0.01), 5.0, 0.05, -8.0),
    "hrg-short-tau": (preset("hrg", tau_s=100.0, delta_inv_tau_per_s=5e-4, theta_tau_deg=5.0, split_hz=0.05,
                             theta_w_deg=40.0, freq_offset_hz=0.03), 50.0, 0.1, 30.0),
}
XI_PER_S = 0.05  # cubic cases: nonlinearity per unit amplitude^2


def truth(params, rate_dps: float, model: str) -> dict[str, float]:
    c = params.coefficients()
    z = dict(zip(free_param_names("linear"), c.zg(math.radians(rate_dps)), strict=True))
    if model != "linear":
        z["xi"] = c.xi
    return z


def run_case(name: str, fs_hz: float, model: str, n_seeds: int, seed0: int = 10_000) -> dict:
    base, rate, k0, th0 = RESONATORS[name]
    params = base.with_(xi_per_s=XI_PER_S) if model == "cubic" else base
    q0 = state_from_elements(1.0, k0, math.radians(th0))
    res = Resonator(params, seed=0, state=q0)
    n = int(round(DURATION_S * fs_hz))
    traj = np.vstack([q0, res.step_block(n, 1.0 / fs_hz, rate_rad_s=math.radians(rate))])
    t = np.arange(n + 1) / fs_hz
    tr = truth(params, rate, model)
    names = tuple(tr)
    bound = crlb_free_decay(duration_s=DURATION_S, stream_hz=fs_hz, noise_sigma=params.noise_sigma, q0=q0,
                            params=tr, model=model)
    crlb = np.array([bound.std[nm] for nm in names])
    err = {"ee": [], "oe": []}
    cover = {"ee": np.zeros(len(names)), "oe": np.zeros(len(names))}
    secs = {"ee": 0.0, "oe": 0.0}
    z_true = np.array([tr[nm] for nm in names])
    for seed in range(n_seeds):
        q = traj + np.random.default_rng(seed0 + seed).normal(0.0, params.noise_sigma, traj.shape)
        for key, method in (("ee", "equation-error"), ("oe", "output-error")):
            t0 = time.perf_counter()
            fit = identify_free_decay(t, *q.T, model=model, method=method)
            secs[key] += time.perf_counter() - t0
            z = np.array([fit.params[nm] for nm in names])
            err[key].append(z - z_true)
            cover[key] += [fit.ci95[nm][0] <= tr[nm] <= fit.ci95[nm][1] for nm in names]
    out = {"names": names, "crlb": crlb}
    for key in ("ee", "oe"):
        e = np.asarray(err[key])
        out[key] = {"ratio": e.std(axis=0, ddof=1) / crlb, "offset": e.mean(axis=0) / crlb,
                    "cover": cover[key] / n_seeds, "sec": secs[key] / n_seeds}
    return out


def band(n_seeds: int) -> tuple[float, float]:
    """The 99 % binomial band around 0.95 for n_seeds draws (normal approximation)."""
    half = 2.5758 * math.sqrt(0.95 * 0.05 / n_seeds)
    return 0.95 - half, 0.95 + half


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=200, help="noise draws per case")
    ap.add_argument("--cubic-seeds", type=int, default=None, help="noise draws per cubic case (default --seeds)")
    ap.add_argument("--case", default="", help="only the cases whose label contains this text")
    ap.add_argument("--seed0", type=int, default=10_000, help="first noise seed")
    args = ap.parse_args()
    n_seeds, only, seed0 = args.seeds, args.case, args.seed0
    n_cubic = args.cubic_seeds if args.cubic_seeds is not None else n_seeds
    worst_oe, bad_cover = 0.0, []
    t_all = time.perf_counter()
    for model in ("linear", "cubic"):
        seeds = n_seeds if model == "linear" else n_cubic
        lo, hi = band(seeds)
        print(f"\n=== {model}: {seeds} seeds per case, {DURATION_S:g} s records; noise seeds from {seed0}; "
              f"coverage target {lo:.3f}..{hi:.3f} (99 % binomial band around 0.95)")
        for fs in (10.0, 100.0):
            for name in RESONATORS:
                label = f"{name} {fs:g} Hz {model}"
                if only and only not in label:
                    continue
                r = run_case(name, fs, model, seeds, seed0)
                print(f"\n{label}: mean fit time ee {r['ee']['sec'] * 1e3:.1f} ms, oe {r['oe']['sec'] * 1e3:.1f} ms")
                print("  param   CRLB std    ee std/CRLB  ee offset  ee cover   oe std/CRLB  oe offset  oe cover")
                for i, nm in enumerate(r["names"]):
                    ee, oe = r["ee"], r["oe"]
                    print(f"  {nm:6s} {r['crlb'][i]:10.3e}  {ee['ratio'][i]:11.2f}  {ee['offset'][i]:9.2f}  "
                          f"{ee['cover'][i]:8.3f}  {oe['ratio'][i]:12.3f}  {oe['offset'][i]:9.2f}  "
                          f"{oe['cover'][i]:8.3f}")
                    worst_oe = max(worst_oe, float(oe["ratio"][i]))
                    if not lo <= oe["cover"][i] <= hi:
                        bad_cover.append((label, nm, float(oe["cover"][i])))
    print(f"\nworst output-error std/CRLB {worst_oe:.3f} (target <= 1.2); output-error coverage outside the band: "
          f"{bad_cover or 'none'}")
    print(f"total {time.perf_counter() - t_all:.0f} s")


if __name__ == "__main__":
    main()
