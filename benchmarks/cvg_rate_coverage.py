"""Benchmark: do the 95 % intervals of the rate-sensor tests hold the truth 95 % of the time?

Part 1, synthetic (bench.analysis.cvg_rate alone, n draws each): the scale factor series of
cvg-scale-factor's default design (R = 20 deg/s, 4 steps, both directions: 18 windows) in
force-to-rebalance (SF 0.9972, bias 29.33 deg/h) and whole-angle (SF -0.277, a 4-theta drift of
29.8 deg/h over random window angles); the static bias from batch means of white rate noise and
of AR(1) rate noise (correlation time 0.5 s, like the loops' filtering) and from batch slopes of
a noisy angle; the turn-on spread (8 turn-ons).  Target: inside the 99 % binomial band around
0.95 (nonlinearity: at least 0.95, its interval is simultaneous).
Part 2, end to end (optional, --seeds N): cvg-scale-factor and cvg-bias on sim-hrg (whole-angle)
and sim-hrg-ftr (force-to-rebalance) with N seeds each, short settings; the fraction of runs
whose intervals hold the truth, and the wall time a run.
Run: .venv/bin/python benchmarks/cvg_rate_coverage.py [n_draws] [--seeds N] [--stations a,b]
(default 2000, 0, sim-hrg,sim-hrg-ftr)
"""

from __future__ import annotations

import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.analysis.cvg_rate import fit_scale_factor, static_bias, turn_on_repeatability  # noqa: E402

RATES = np.concatenate([np.linspace(-20, 20, 9), np.linspace(20, -20, 9)])


def _band(n: int) -> tuple[float, float]:
    half = 2.5758 * math.sqrt(0.95 * 0.05 / n)
    return 0.95 - half, 0.95 + half


def scale_factor_coverage(n: int, rng: np.random.Generator) -> None:
    for mode, sf, bias, drift in (("force-to-rebalance", 0.9972, 29.33, 0.0), ("whole-angle", -0.277, 0.0, 2.29e-3)):
        hits = np.zeros(4)
        widths = []
        for _ in range(n):
            y = sf * (RATES + bias / 3600.0) + rng.normal(0, 3e-4, len(RATES))
            basis = None
            if drift:
                th = rng.uniform(0, 2 * math.pi, len(RATES))
                basis = np.column_stack([np.cos(th), np.sin(th)])
                y += drift * basis[:, 1]
            f = fit_scale_factor(RATES, y, drift_basis=basis)
            hits += [f.scale_factor_ci95[0] <= sf <= f.scale_factor_ci95[1],
                     f.bias_dph_ci95[0] <= bias <= f.bias_dph_ci95[1],
                     f.asymmetry_ppm_ci95[0] <= 0 <= f.asymmetry_ppm_ci95[1], f.nonlinearity_ppm_ci95[0] <= 0]
            widths.append(0.5 * (f.scale_factor_ci95[1] - f.scale_factor_ci95[0]) / abs(sf) * 1e6)
        c = hits / n
        print(f"  {mode:19s} SF {c[0]:.3f}  bias {c[1]:.3f}  asymmetry {c[2]:.3f}  nonlinearity (>= 0.95) {c[3]:.3f}"
              f"  (SF half-width {np.mean(widths):.1f} ppm)")


def _ar1(rng, n: int, rho: float, sigma: float) -> np.ndarray:
    e = rng.normal(0, sigma * math.sqrt(1 - rho**2), n)
    x = np.empty(n)
    x[0] = rng.normal(0, sigma)
    for i in range(1, n):
        x[i] = rho * x[i - 1] + e[i]
    return x


def bias_coverage(n: int, rng: np.random.Generator) -> None:
    t = np.arange(6000) / 100.0
    truth = 29.33
    cases = {"white rate": 0, "AR(1) rate, 0.5 s": 0, "angle slopes": 0}
    for _ in range(n):
        y = 0.9972 * truth / 3600 + rng.normal(0, 0.01, len(t))
        b = static_bias(t, y, mode="force-to-rebalance", scale_factor=0.9972)
        cases["white rate"] += b.ci95[0] <= truth <= b.ci95[1]
        y = 0.9972 * truth / 3600 + _ar1(rng, len(t), math.exp(-0.01 / 0.5), 0.01)
        b = static_bias(t, y, mode="force-to-rebalance", scale_factor=0.9972)
        cases["AR(1) rate, 0.5 s"] += b.ci95[0] <= truth <= b.ci95[1]
        ang = -0.277 * truth / 3600 * t + rng.normal(0, 1e-3, len(t))
        b = static_bias(t, ang, mode="whole-angle", scale_factor=-0.277)
        cases["angle slopes"] += b.ci95[0] <= truth <= b.ci95[1]
    print("  static bias: " + "  ".join(f"{k} {v / n:.3f}" for k, v in cases.items()))
    hits = 0
    for _ in range(n):
        b = 29.33 + rng.normal(0, 2.0, 8) + rng.normal(0, 0.5, 8)
        r = turn_on_repeatability(b, np.full(8, 0.5))
        hits += r.ci95[0] <= 2.0 <= r.ci95[1]
    print(f"  turn-on spread 2 deg/h, 8 turn-ons, records 0.5 deg/h: {hits / n:.3f}")


def end_to_end(seeds: int, stations: tuple[str, ...] = ("sim-hrg", "sim-hrg-ftr")) -> None:
    from bench.composition.sim_station import SimStation
    from bench.engine import Runner
    from bench.results import ResultsStore
    from procedures.cvg_bias import CvgBias
    from procedures.cvg_scale_factor import CvgScaleFactor

    plans = ((CvgScaleFactor, {"max_rate_dps": 36.0, "steps": 2, "average_s": 20.0, "settle_s": 3.0},
              ("scale_factor", "bias_dph", "asymmetry_ppm")),
             (CvgBias, {"record_s": 20.0, "turn_ons": 3, "quench_s": 6.0, "settle_s": 30.0}, ("bias_dph",)))
    for cls, params, names in plans:
        for station_name in stations:
            hits = {n: 0 for n in names}
            wall = []
            errs: dict[str, list[float]] = {n: [] for n in names}
            for seed in range(seeds):
                with tempfile.TemporaryDirectory() as tmp:
                    station = SimStation(station_name, seed=seed).open()
                    store = ResultsStore(Path(tmp) / "r.sqlite")
                    try:
                        t0 = time.perf_counter()
                        extra = {"scale_factor": 0.9972} if cls is CvgBias and station_name.endswith("-ftr") else {}
                        rec = Runner(station, runs_dir=Path(tmp) / "runs", store=store).run(cls, params | extra)
                        wall.append(time.perf_counter() - t0)
                        truth = cls.truth_for(station.truth())
                    finally:
                        store.close()
                        station.close()
                got = {r.name: r for r in rec.measurements}
                for n in names:
                    lo, hi = got[n].ci95
                    hits[n] += lo <= truth[n] <= hi
                    errs[n].append(got[n].value - truth[n])
            print(f"  {cls.name:17s} {station_name:12s} " + "  ".join(
                f"{n} {hits[n]}/{seeds} (error mean {np.mean(errs[n]):.3g}, "
                f"rms {np.sqrt(np.mean(np.square(errs[n]))):.3g})"
                for n in names)
                + f"  wall {np.median(wall):.1f} s a run")


def main() -> None:
    args = sys.argv[1:]
    seeds = 0
    if "--seeds" in args:
        i = args.index("--seeds")
        seeds = int(args[i + 1])
        del args[i : i + 2]
    stations = ("sim-hrg", "sim-hrg-ftr")
    if "--stations" in args:
        i = args.index("--stations")
        stations = tuple(args[i + 1].split(","))
        del args[i : i + 2]
    n = int(args[0]) if args else 2000
    lo, hi = _band(n)
    rng = np.random.default_rng(20261123)
    print(f"{n} draws; 99 % band around 0.95: {lo:.3f}..{hi:.3f}")
    t0 = time.perf_counter()
    scale_factor_coverage(n, rng)
    bias_coverage(n, rng)
    print(f"  ({time.perf_counter() - t0:.1f} s)")
    if seeds:
        print(f"end to end, {seeds} seeds a station:")
        end_to_end(seeds, stations)


if __name__ == "__main__":
    main()
