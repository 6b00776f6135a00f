"""Where hrg-damping's mean verification drift comes from (issue 31 item 8; docs/damping_drift.md).

1. The estimator on a synthetic noise-free angle record with a pure 4 theta drift (exact RK4
   integration of dtheta/dt = Omega + A sin 4(theta - theta_tau)): the fitted mean must be ~0.
2. hrg-damping on sim-hrg's resonator with the split, the damping anisotropy and the pickoff noise
   switched off one at a time (noise-free runs resolve the mean to 1e-4 deg/h).
3. In each run's raw record, the drift the frequency split makes of the residual quadrature,
   -(Dw/2) (k/a) cos 4(theta - theta_w) (docs/damping_drift.md), averaged over the record, beside
   the fitted mean.

Run: PYTHONPATH=. .venv/bin/python benchmarks/damping_mean_drift.py   (about 1 min)
"""

from __future__ import annotations

import json
import math
import tempfile

import h5py
import numpy as np

from bench.analysis.damping import fit_angle_harmonics
from bench.analysis.slow_model import orbit_elements
from bench.composition.sim_station import SimStation
from bench.engine import Runner
from procedures.hrg_damping import HrgDamping
from simulators.physics.params import preset


def synthetic_mean_dph(rate_dps: float, amp_dph: float, k: float, theta_tau_deg: float = 20.0,
                       record_s: float = 90.0, fs_hz: float = 1000.0) -> float:
    """The angle fit's mean on an exactly integrated pure 4 theta drift (output-referred deg/h)."""
    to_dph = math.degrees(1.0 / k) * 3600.0
    om, amp, th0 = math.radians(rate_dps), amp_dph / to_dph, math.radians(theta_tau_deg)
    n, sub = int(record_s * fs_hz), 20
    h = 1.0 / fs_hz / sub
    th, x = np.empty(n), 0.3

    def f(y: float) -> float:
        return om + amp * math.sin(4.0 * (y - th0))

    for i in range(n):
        th[i] = x
        for _ in range(sub):
            k1 = f(x)
            k2 = f(x + h / 2 * k1)
            k3 = f(x + h / 2 * k2)
            k4 = f(x + h * k3)
            x += h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    t = np.arange(n) / fs_hz
    return fit_angle_harmonics(t, th, om).drift.scaled(to_dph).mean


def split_drift_dph(raw_file: str, split_hz: float, theta_w_deg: float, k: float, rate_dps: float) -> list[tuple]:
    """Per verification record (off, on): the fitted mean and the time mean of -(Dw/2)(k/a)cos 4(theta - theta_w)."""
    to_dph = math.degrees(1.0 / k) * 3600.0
    dw, thw = 2 * math.pi * split_hz, math.radians(theta_w_deg)
    with h5py.File(raw_file) as f:
        d = f["streams/fpga"]
        col = dict(zip(json.loads(d.attrs["columns"]), d[:].T, strict=True))
        windows = f["streams/damping_windows"][:]
    out = []
    for _kind, t0, t1 in windows[1:]:
        m = (col["t_s"] >= t0) & (col["t_s"] <= t1)
        el = orbit_elements(np.column_stack([col[c][m] for c in ("cx", "sx", "cy", "sy")]))
        th = np.unwrap(4.0 * el["theta_rad"]) / 4.0
        k_rel = el["k"] / el["a"]
        fitted = fit_angle_harmonics(col["t_s"][m], th, math.radians(rate_dps)).drift.scaled(to_dph).mean
        split = float(np.mean(-(dw / 2) * k_rel * np.cos(4.0 * (th - thw)))) * to_dph
        out.append((fitted, split, float(np.std(k_rel))))
    return out


def main() -> None:
    k = preset("hrg").bryan_factor
    print("1. estimator, noise-free synthetic 4 theta drift of 29.8 deg/h, 90 s at 1 kHz: fitted mean (deg/h)")
    for rate in (1.0, 2.0, 4.0):
        print(f"   {rate:g} deg/s: {synthetic_mean_dph(rate, 29.8, k):+.1e}")
    print("\n2./3. hrg-damping (defaults, seed 0) on sim-hrg's resonator with parts switched off (deg/h):")
    print("   resonator                   record  fitted mean  split x quadrature  rms k/a")
    tmp = tempfile.mkdtemp(prefix="gyrobench-mean-drift-")
    cases = {"hrg (as sim-hrg)": {}, "no damping anisotropy": {"delta_inv_tau_per_s": 0.0},
             "no split": {"split_hz": 0.0}, "no pickoff noise": {"noise_sigma": 0.0},
             "no split, no noise": {"split_hz": 0.0, "noise_sigma": 0.0}}
    for label, over in cases.items():
        params = preset("hrg", **over)
        station = SimStation("sim-hrg", seed=0, resonator=params).open()
        try:
            rec = Runner(station, runs_dir=tmp).run(HrgDamping, {})
        finally:
            station.close()
        for name, (fitted, split, k_rms) in zip(("off", "on"), split_drift_dph(
                rec.raw_file, params.split_hz, params.theta_w_deg, k, HrgDamping.verify_rate_dps.default),
                strict=True):
            print(f"   {label:27s} {name:6s} {fitted:+11.4f}  {split:+18.4f}  {k_rms:.1e}")


if __name__ == "__main__":
    main()
