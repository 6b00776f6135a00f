"""How often each parameter's truth falls outside its 95 % interval, over seeds: model error or
chance (issue 31, item 8).

Runs hrg-free-decay on sim-hrg (lockstep, short settings: record_s 20 s at 20 deg/s, as the report
test) for N seeds through the real runner, and counts per measurement the seeds whose truth lies
outside the value's 95 % interval (an axis angle's truth by its nearest image,
bench.numbers.truth_outside).  With honest intervals the count is Binomial(N, 0.05); a count
above the binomial band's 99.5 % quantile (N = 20: 4 or more) is not chance: the interval or the
model is wrong for that parameter.
Run: PYTHONPATH=. .venv/bin/python benchmarks/truth_flags.py [n_seeds] [procedure] [--set NAME=VALUE ...]
     [--station NAME] (default sim-hrg)
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from collections import defaultdict
from math import nan

import numpy as np
from scipy import stats

from bench.composition.sim_station import SimStation
from bench.engine import Runner
from bench.numbers import truth_outside
from procedures import find_procedure

SHORT = {"hrg-free-decay": {"record_s": 20.0, "rate_dps": 20.0}}


def outside_counts(name: str, params: dict, seeds: range, station: str = "sim-hrg") -> tuple[dict, dict, int, dict]:
    """({measurement: seeds outside}, {measurement: seeds compared}, runs, {measurement: [value - truth
    per seed]}) over the seeds (the deviations of non-periodic measurements: a bias shows in their mean)."""
    cls = find_procedure(name)
    periods = cls.truth_periods()
    outside, compared, deviation = defaultdict(int), defaultdict(int), defaultdict(list)
    with tempfile.TemporaryDirectory() as tmp:
        for seed in seeds:
            st = SimStation(station, seed=seed).open()
            try:
                rec = Runner(st, runs_dir=tmp).run(cls, params)
            finally:
                st.close()
            js = rec.as_json()
            truth = cls.truth_for(js["truth"])
            for m, r in js["measurements"].items():
                if m not in truth:
                    continue
                flag = truth_outside(r["value"], truth[m], r["ci95"], periods.get(m))
                if flag is not None:
                    compared[m] += 1
                    outside[m] += bool(flag)
                    if m not in periods:
                        deviation[m].append(r["value"] - truth[m])
    return dict(outside), dict(compared), len(seeds), dict(deviation)


def band(n: int, p: float = 0.05, q: float = 0.995) -> int:
    """The largest count of n that chance alone reaches with probability 1 - q or more."""
    return int(stats.binom.ppf(q, n, p))


def main(argv: list[str]) -> None:
    n = int(argv[0]) if argv and argv[0].isdigit() else 20
    name = argv[1] if len(argv) > 1 and not argv[1].startswith("--") else "hrg-free-decay"
    params = dict(SHORT.get(name, {}))
    station = "sim-hrg"
    for i, a in enumerate(argv):
        if a == "--set":
            k, _, v = argv[i + 1].partition("=")
            params[k] = v
        if a == "--station":
            station = argv[i + 1]
    t0 = time.perf_counter()
    outside, compared, runs, deviation = outside_counts(name, params, range(1, n + 1), station)
    hi = band(n)
    print(f"{name} on {station} {params}: {runs} seeds in {time.perf_counter() - t0:.0f} s; chance alone: "
          f"0..{hi} of {n} outside (Binomial({n}, 0.05), 99.5 %)")
    print(f"{'measurement':30s} {'outside':>8s} {'of':>4s}  {'mean(value - truth)':>20s} {'sd':>10s}  verdict")
    rows = []
    for m in sorted(compared, key=lambda k: (-outside.get(k, 0), k)):
        k, c = outside.get(m, 0), compared[m]
        verdict = "model error (above the band)" if k > band(c) else "chance"
        dev = np.asarray(deviation.get(m, []), dtype=float)
        mean, sd = (float(dev.mean()), float(dev.std(ddof=1)) if len(dev) > 1 else 0.0) if len(dev) else (nan, nan)
        rows.append({"measurement": m, "outside": k, "compared": c, "verdict": verdict,
                     "mean_deviation": mean, "sd_deviation": sd})
        print(f"{m:30s} {k:8d} {c:4d}  {mean:20.4g} {sd:10.3g}  {verdict}")
    total_k, total_c = sum(outside.values()), sum(compared.values())
    print(f"all: {total_k} of {total_c} truths outside ({100.0 * total_k / max(total_c, 1):.1f} %, 5 % expected)")
    print(json.dumps({"procedure": name, "params": params, "seeds": n, "rows": rows}))


if __name__ == "__main__":
    main(sys.argv[1:])
