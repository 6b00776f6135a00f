"""From a unit's calibration runs to its trims in NVM, on the simulated HRG station: run
hrg-damping and hrg-free-decay (defaults), build the compensation file from the store's rows
(`from_runs`), load it into the FPGA (`load_trims`: write, commit, reload, compare), then hold the
wave 22.5 deg off the true damping axis in whole-angle mode with only the trims compensating, and
measure its true drift.  Prints each coefficient's error against the truth in units of its U.

    .venv/bin/python benchmarks/compensation_end_to_end.py [SEED]
"""

from __future__ import annotations

import math
import sys
import tempfile
import time

import numpy as np

from bench.analysis.slow_model import orbit_elements, state_from_elements
from bench.composition.sim_station import SimStation
from bench.engine import Runner
from bench.line.compensation import from_runs
from bench.line.fpga_cli import load_trims
from bench.results import ResultsStore
from procedures.hrg_damping import HrgDamping
from procedures.hrg_free_decay import HrgFreeDecay
from simulators.probes import EndStateProbe


def _true_drift_dps(station, theta_deg: float, record_s: float = 40.0) -> float:
    world, fpga = station.world, station.devices["fpga"]
    with world.lock:
        world.resonator.set_state(state_from_elements(1.0, 0.0, math.radians(theta_deg)))
    fpga.set_pll(True, world.params.f0_hz)
    fpga.set_agc(True, 1.0)
    fpga.set_quadrature_loop(True)
    fpga.set_whole_angle(True, 0.0)
    fpga.set_drive_enabled(True)
    station.clock.sleep(10.0)
    tap = EndStateProbe()
    world.attach(tap)
    station.clock.sleep(record_s)
    world.detach(tap)
    fpga.safe_state()
    theta = np.unwrap(4.0 * orbit_elements(np.array(tap.q))["theta_rad"]) / 4.0
    return math.degrees(np.polyfit(np.array(tap.t_s), theta, 1)[0])


def main() -> None:
    seed = int(sys.argv[1]) if len(sys.argv) > 1 else 0
    tmp = tempfile.mkdtemp(prefix="gyrobench-comp-")
    store = ResultsStore(f"{tmp}/results.sqlite")
    station = SimStation("sim-hrg", seed=seed).open()
    try:
        t0 = time.perf_counter()
        runner = Runner(station, runs_dir=tmp, store=store, duts=["SIM-0001"])
        ids = [runner.run(cls, {}).run_id for cls in (HrgDamping, HrgFreeDecay)]
        wall = time.perf_counter() - t0
        truth = station.truth()
        comp = from_runs("SIM-0001", [store.get_run(i) for i in ids])
        out = load_trims(station.devices["fpga"], comp.trims())
        d_dps = math.degrees(truth["delta_inv_tau_per_s"] / 4)
        theta = truth["theta_tau_deg"] + 22.5
        drift = _true_drift_dps(station, theta)
    finally:
        station.close()
    print(f"sim-hrg seed {seed}: hrg-damping + hrg-free-decay in {wall:.0f} s wall; NVM CRC {out['crc']:#06x}")
    print("| coefficient | identified | U (- / +) | truth | error / U |")
    print("|---|---|---|---|---|")
    for name, c in comp.coefficients.items():
        t = truth.get(name)
        err = c.value - t if t is not None else math.nan
        if name.endswith("_deg") and t is not None:
            err = math.remainder(err, 90.0)
        u = c.u_high if err > 0 else c.u_low
        ratio = f"{err / u:+.2f}" if u else "—"
        us = f"{c.u_low:.3g} / {c.u_high:.3g}" if c.u_low is not None else "—"
        print(f"| {name} ({c.procedure}) | {c.value:.6g} | {us} | {t if t is None else f'{t:.6g}'} | {ratio} |")
    print(f"true drift at theta_tau + 22.5 deg, trims only: {drift:+.3e} deg/s = {100 * abs(drift) / d_dps:.2f} % "
          f"of the untrimmed D/4 = {d_dps:.3e} deg/s")


if __name__ == "__main__":
    main()
