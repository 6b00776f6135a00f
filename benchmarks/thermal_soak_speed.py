"""Speed and numbers of a full thermal soak (issue 34's benchmark): thermal-soak on sim-hrg-thermal
(the realistic HRG in force-to-rebalance, a Watlow F4 chamber at 3 deg/min, the case 20 min behind
the air), real drivers over loopback, lockstep.  Prints the simulated and wall time and the fits.
Target: 10 temperatures, ~6 simulated hours, in at most 3 wall minutes.

Run: .venv/bin/python benchmarks/thermal_soak_speed.py [--points 10] [--settle-ppm-per-min 0.05]

Measured: see docs/chamber.md ("Measured").
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from bench.composition.sim_station import SimStation
from bench.engine import Runner
from procedures.thermal_soak import ThermalSoak


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--points", type=int, default=10)
    ap.add_argument("--low-degc", type=float, default=-40.0)
    ap.add_argument("--high-degc", type=float, default=85.0)
    ap.add_argument("--settle-ppm-per-min", type=float, default=0.05)
    ap.add_argument("--record-s", type=float, default=300.0)
    args = ap.parse_args()
    params = {"t_low_degc": args.low_degc, "t_high_degc": args.high_degc, "points": args.points,
              "settle_ppm_per_min": args.settle_ppm_per_min, "record_s": args.record_s}
    with tempfile.TemporaryDirectory() as tmp, SimStation("sim-hrg-thermal", seed=0) as station:
        t0 = time.monotonic()
        rec = Runner(station, runs_dir=Path(tmp) / "runs").run(ThermalSoak, params)
        wall = time.monotonic() - t0
        truth = ThermalSoak.truth_for(station.truth())
    sim_h = rec.simulated_s / 3600.0
    print(f"outcome {rec.outcome}; {sim_h:.2f} simulated h in {wall / 60:.2f} wall min "
          f"({sim_h / (wall / 60):.2f} sim h / wall min)")
    for m in rec.measurements:
        ci = "" if m.ci95 is None else f" [{m.ci95[0]:.9g}, {m.ci95[1]:.9g}]"
        tv = truth.get(m.name)
        print(f"  {m.name} = {m.value:.9g}{ci} {m.unit}" + ("" if tv is None else f"  (truth {tv:.9g})"))


if __name__ == "__main__":
    main()
