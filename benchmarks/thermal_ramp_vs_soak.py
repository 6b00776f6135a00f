"""The ramp method against the soak on the same simulated unit (issue 34's benchmark):
thermal-soak then thermal-ramp on one station (the realistic HRG in force-to-rebalance in a
Watlow F4 chamber, by default sim-hrg-thermal with the resonator `--resonator-tau-s` behind its
case), each from a fresh station of the same seed.  Prints each method's simulated and wall time,
its coefficients with intervals beside the simulator's truth, and the bias residual each leaves
at the soak's settled points (the soak's own fit there, the ramp's fit against the part
thermocouple and against the frequency thermometer applied to them).  Target: the ramp within
1.5x of the soak's residual in at most a third of its simulated time.

Run: .venv/bin/python benchmarks/thermal_ramp_vs_soak.py [--station sim-hrg-thermal] [--points 10]

Measured: see docs/chamber.md ("The ramp method").
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from bench.composition.sim_station import SimStation
from bench.engine import Runner
from bench.recorder import open_run
from bench.station_config import find_station_file, load_config
from procedures.thermal_ramp import ThermalRamp
from procedures.thermal_soak import ThermalSoak


def _station_file(name: str, resonator_tau_s: float, tmp: Path) -> Path:
    """The station's file with the chamber's resonator_tau_s set (a copy in tmp)."""
    lines = find_station_file(name).read_text().splitlines()
    lines = [ln for ln in lines if not ln.startswith("resonator_tau_s")]
    at = lines.index("[devices.chamber]") + 1
    lines.insert(at, f"resonator_tau_s = {resonator_tau_s!r}")
    path = tmp / f"{name}.toml"
    path.write_text("\n".join(lines) + "\n")
    return path


def _run(path: Path, proc, params: dict, runs: Path):
    with SimStation(load_config(path), seed=0) as station:
        t0 = time.monotonic()
        rec = Runner(station, runs_dir=runs).run(proc, params)
        wall = time.monotonic() - t0
        truth = proc.truth_for(station.truth())
    print(f"{proc.name}: outcome {rec.outcome}; {rec.simulated_s / 3600:.2f} simulated h in {wall / 60:.2f} wall min")
    for m in rec.measurements:
        ci = "" if m.ci95 is None else f" [{m.ci95[0]:.6g}, {m.ci95[1]:.6g}]"
        tv = truth.get(m.name)
        print(f"  {m.name} = {m.value:.6g}{ci} {m.unit}" + ("" if tv is None else f"  (truth {tv:.6g})"))
    return rec


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--station", default="sim-hrg-thermal")
    ap.add_argument("--resonator-tau-s", type=float, default=300.0)
    ap.add_argument("--points", type=int, default=10)
    ap.add_argument("--low-degc", type=float, default=-40.0)
    ap.add_argument("--high-degc", type=float, default=85.0)
    ap.add_argument("--settle-ppm-per-min", type=float, default=0.5)
    ap.add_argument("--record-s", type=float, default=300.0)
    ap.add_argument("--cycle-degc-per-min", type=float, default=2.0)
    ap.add_argument("--segment-s", type=float, default=300.0)
    ap.add_argument("--tail-s", type=float, default=2400.0)
    args = ap.parse_args()
    common = {"t_low_degc": args.low_degc, "t_high_degc": args.high_degc,
              "settle_ppm_per_min": args.settle_ppm_per_min, "max_order": 3}
    with tempfile.TemporaryDirectory() as tmp:
        path = _station_file(args.station, args.resonator_tau_s, Path(tmp))
        soak = _run(path, ThermalSoak, common | {"points": args.points, "record_s": args.record_s}, Path(tmp) / "a")
        ramp = _run(path, ThermalRamp, common | {"cycle_degc_per_min": args.cycle_degc_per_min,
                                                 "segment_s": args.segment_s, "tail_s": args.tail_s}, Path(tmp) / "b")
        sp = ThermalSoak(soak.params).points_table(open_run(soak.raw_file))
        _, s_bias, _ = ThermalSoak(soak.params).fits(open_run(soak.raw_file))
        rp, r_bias, _, line = ThermalRamp(ramp.params).fits(open_run(ramp.raw_file))
    # the soak's settled points, compensated by each fit (the frequency thermometer reads the soak's
    # frequencies through the ramp's own line)
    t_freq = 25.0 + (sp["f0_hz"] - line.coeffs[0]) / line.coeffs[1]
    rms = {
        "soak fit (its own points)": s_bias(sp["part_c"]),
        "ramp fit vs part thermocouple": r_bias["part"](sp["part_c"]),
        "ramp fit vs frequency thermometer": r_bias["frequency"](t_freq),
        "ramp fit vs chamber air": r_bias["air"](sp["part_c"]),  # settled: the air at the case
    }
    print(f"simulated time ramp / soak: {ramp.simulated_s / soak.simulated_s:.3f}")
    print(f"bias residual at the soak's {len(sp['part_c'])} settled points (rms, deg/h; their mean standard error "
          f"{np.sqrt(np.mean(sp['bias_se_dph'] ** 2)):.3f}):")
    for k, fit in rms.items():
        print(f"  {k}: {np.sqrt(np.mean((sp['bias_dph'] - fit) ** 2)):.4f}")


if __name__ == "__main__":
    main()
