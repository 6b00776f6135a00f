"""The ramp method against the soak on the same simulated unit (issue 34's benchmark):
thermal-soak then thermal-ramp on one station (the realistic HRG in force-to-rebalance in a
Watlow F4 chamber, by default sim-hrg-thermal with the resonator `--resonator-tau-s` behind its
case), each from a fresh station of the same seed.  Prints each method's simulated and wall time,
its coefficients with intervals beside the simulator's truth, and the bias residual each leaves
at the soak's settled points (the soak's own fit there, the ramp's fit against the part
thermocouple, the frequency thermometer and the chamber air applied to them: the numbers
`gyrobench report RAMP --against SOAK` shows, from bench.reporting.thermal_compare; `--report DIR`
writes that page).  Target: the ramp within 1.5x of the soak's residual in at most a third of its
simulated time.

Run: .venv/bin/python benchmarks/thermal_ramp_vs_soak.py [--station sim-hrg-thermal] [--points 10]

Measured: see docs/chamber.md ("The ramp method").
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from bench.composition.sim_station import SimStation
from bench.engine import Runner
from bench.recorder import open_run
from bench.reporting.thermal_compare import compare, write_comparison
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
    ap.add_argument("--report", default=None, metavar="DIR",
                    help="keep both runs in DIR and write the comparison page there")
    args = ap.parse_args()
    common = {"t_low_degc": args.low_degc, "t_high_degc": args.high_degc,
              "settle_ppm_per_min": args.settle_ppm_per_min, "max_order": 3}
    with tempfile.TemporaryDirectory() as tmp:
        path = _station_file(args.station, args.resonator_tau_s, Path(tmp))
        runs = Path(args.report) if args.report else Path(tmp)
        soak = _run(path, ThermalSoak, common | {"points": args.points, "record_s": args.record_s}, runs)
        ramp = _run(path, ThermalRamp, common | {"cycle_degc_per_min": args.cycle_degc_per_min,
                                                 "segment_s": args.segment_s, "tail_s": args.tail_s}, runs)
        with open_run(soak.raw_file) as s_data, open_run(ramp.raw_file) as r_data:
            cmp, _ = compare(s_data, r_data)  # what `gyrobench report RAMP --against SOAK` shows
        if args.report:
            print("page:", *write_comparison(ramp.raw_file, soak.raw_file))
    print(f"simulated time ramp / soak: {cmp.time_ratio:.3f}")
    print(f"bias residual at the soak's {len(cmp.part_c)} settled points (rms, deg/h; their mean standard error "
          f"{cmp.noise_rms_dph:.3f}):")
    for c in (cmp.soak, *cmp.ramp.values()):
        print(f"  {c.label}: {c.rms_dph:.4f} ({c.ratio:.2f}x the soak's)")
    print(f"target (best ramp thermometer within 1.5x in at most 1/3 of the time): "
          f"{'met' if cmp.meets_target() else 'not met'}")

if __name__ == "__main__":
    main()
