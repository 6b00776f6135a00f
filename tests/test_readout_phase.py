"""Readout phase trim and its calibration (issue 33 item 3; docs/readout_phase.md): the FPGA's
TRIM_PHASE_X/Y_DEG undo a chain delay exactly, the amplitude loop's response to the
frequency-control force reads the delay, and nulling it pass after pass finds each chain's delay."""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import math

import numpy as np
import pytest

from bench.analysis import readout_phase as rp
from bench.analysis.slow_model import state_from_elements
from drivers.fpga import protocol as p
from simulators.fpga import kernels as k
from simulators.fpga.firmware import FpgaFirmware, _turn_back
from simulators.physics.errors import ERROR_PRESETS, ErrorSources
from simulators.physics.params import preset
from simulators.world import World

DELAY = ErrorSources(pickoff_phase_x_deg=2.0, pickoff_phase_y_deg=2.05)
F_HZ, RATE_HZ = 0.01, 0.025
#: the self-calibrated bias stability on sim-hrg-realistic, seed 0, 3 cycles at 0.25 deg/s: measured 0.80 deg/h
#: (141.5 without the phase calibration; 1.27 before the FPGA's frequency-control force took the
#: orbit's quadrature into its direction; the floor 0.52)
SELFCAL_REALISTIC_DPH = 1.0


def test_the_trim_undoes_the_chains_delay():
    """errors.measure delays each chain by its phase; _turn_back with the same trims gives the states back."""
    q = np.random.default_rng(0).normal(size=(50, 4))
    px, py = math.radians(2.0), math.radians(2.05)
    back = _turn_back(DELAY.measure(q, 0.0), (math.cos(px), math.sin(px), math.cos(py), math.sin(py)))
    assert np.max(np.abs(back - q)) < 1e-14


def test_the_compiled_trim_gives_the_numpy_forms_numbers_bit_for_bit():
    """kernels.turn_back (behind _turn_back) against the numpy form it replaced: the very same bits
    (seeded runs stay bit-identical)."""
    rng = np.random.default_rng(3)
    for _ in range(50):
        q = rng.normal(0.0, rng.uniform(0.01, 3.0), (int(rng.integers(1, 300)), 4))
        px, py = np.radians(rng.uniform(-10.0, 10.0, 2))
        cpx, spx, cpy, spy = math.cos(px), math.sin(px), math.cos(py), math.sin(py)
        want = np.stack([q[:, 0] * cpx + q[:, 1] * spx, -q[:, 0] * spx + q[:, 1] * cpx,
                         q[:, 2] * cpy + q[:, 3] * spy, -q[:, 2] * spy + q[:, 3] * cpy], axis=1)  # fmt: skip
        assert _turn_back(q, (cpx, spx, cpy, spy)).tobytes() == want.tobytes()


class _Loops:
    def __init__(self, fw: FpgaFirmware) -> None:
        self.fw, self.rows = fw, []

    def before_block(self, *args) -> None:
        pass

    def after_block(self, world, block) -> None:
        st = self.fw._st
        self.rows.append((float(block.t_s[-1]), float(st[k.S_OUT]), float(st[k.S_OUT + 1]), float(st[k.S_THETA])))


def _gyro(errors: ErrorSources) -> tuple[World, FpgaFirmware, _Loops]:
    params = preset("hrg", noise_sigma=0.0)
    world = World(params, seed=1, errors=errors)
    world.resonator.set_state(state_from_elements(1.0, 0.0, 0.0))
    fw = FpgaFirmware(world)
    world.attach(fw)
    for name, value in (("REF_FREQ_HZ", params.f0_hz), ("AGC_SETPOINT", 1.0), ("FM_FORCE_HZ", F_HZ),
                        ("FM_RATE_HZ", RATE_HZ)):
        fw.write(p.BY_NAME[name], value)
    fw.write(p.BY_NAME["CTRL"], p.DRIVE_EN | p.AGC_EN | p.PLL_EN | p.QUAD_EN | p.WHOLE_ANGLE)
    world.advance(20.0)
    rec = _Loops(fw)
    world.attach(rec)
    return world, fw, rec


def _hold(world: World, rec: _Loops, hold_s: float = 120.0) -> rp.PhaseReading:
    rec.rows.clear()
    world.advance(hold_s)
    t, amp, f, th = np.array(rec.rows).T
    return rp.read_phase(t, th, amp, f, fm_force_hz=F_HZ, fm_rate_hz=RATE_HZ)


def test_one_reading_sees_the_delay_and_none_without_it():
    """Wave on the x chain, noise-free: the reading is x's 2 deg to 1.5 % (the loops' own scale
    error: 2.023 read), and 0 to 1e-5 deg on a chain without delay."""
    world, _fw, rec = _gyro(DELAY)
    r = _hold(world, rec)
    assert r.phase_deg == pytest.approx(2.0, rel=0.015), r
    world, _fw, rec = _gyro(ErrorSources())
    assert abs(_hold(world, rec).phase_deg) < 1e-5


def test_three_nulling_passes_find_each_chains_delay_on_the_realistic_unit():
    """Every error source of hrg-realistic (gains, electrode angles, nonlinearity, delays 2.0 / 2.05
    deg), noise-free: three passes of (hold, turn 45 deg, hold, trim) leave trims within 0.0005 deg
    of each chain's delay (measured 0.0002 / 0.00002), inside the procedure's 0.001 deg floor."""
    errors = ERROR_PRESETS["hrg-realistic"]
    world, fw, rec = _gyro(errors)
    trim, sign = np.zeros(2), 1.0
    for _ in range(3):
        r1 = _hold(world, rec)
        fw.write(p.BY_NAME["PRECESSION_RATE_DPS"], sign * 1.0)
        world.advance(45.0)
        fw.write(p.BY_NAME["PRECESSION_RATE_DPS"], 0.0)
        world.advance(10.0)
        sign = -sign
        res, _cov = rp.channel_phases([r1, _hold(world, rec)], floor_deg=1e-6)
        trim += res
        fw.write(p.BY_NAME["TRIM_PHASE_X_DEG"], trim[0])
        fw.write(p.BY_NAME["TRIM_PHASE_Y_DEG"], trim[1])
        fw.write(p.BY_NAME["TRIM_EN"], p.TRIM_PHASE)
        world.advance(10.0)
    assert trim[0] == pytest.approx(errors.pickoff_phase_x_deg, abs=5e-4), trim
    assert trim[1] == pytest.approx(errors.pickoff_phase_y_deg, abs=5e-4), trim
    assert fw.truth()["trim_phase_x_deg"] == trim[0]


def test_readings_at_one_angle_cannot_separate_the_chains():
    r = rp.PhaseReading(0.0, 2.0, 1e-4, -0.44, 1.0, 6)
    with pytest.raises(ValueError, match="do not separate"):
        rp.channel_phases([r, r])


def test_selfcal_on_the_realistic_unit_calibrates_the_phase_first():
    """hrg-selfcal on sim-hrg-realistic (every error source of docs/error_sources.md), seed 0, 3
    cycles at 0.25 deg/s with 3 passes of the phase calibration: each chain's delay (2.0 / 2.05 deg)
    inside its interval, and the self-calibrated bias stability under SELFCAL_REALISTIC_DPH (141.5 deg/h
    without the calibration, the delay's split leak; docs/readout_phase.md)."""
    import tempfile

    from bench.composition.sim_station import SimStation
    from bench.engine import Runner
    from procedures.hrg_selfcal import HrgSelfcal

    station = SimStation("sim-hrg-realistic", seed=0).open()
    try:
        record = Runner(station, runs_dir=tempfile.mkdtemp(prefix="gyrobench-test-")).run(
            HrgSelfcal, {"cycles": 3, "precession_dps": 0.25, "settle_s": 10.0, "phase_cal": 3})
        truth = station.truth()
    finally:
        station.close()
    m = {r.name: r for r in record.measurements}
    for ax in ("x", "y"):
        lo, hi = m[f"readout_phase_{ax}_deg"].ci95
        assert lo <= truth[f"err_pickoff_phase_{ax}_deg"] <= hi, m[f"readout_phase_{ax}_deg"]
    assert m["bias_stability_selfcal_dph"].value < SELFCAL_REALISTIC_DPH, m["bias_stability_selfcal_dph"]
