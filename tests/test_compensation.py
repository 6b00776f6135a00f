"""Trims in the simulated FPGA's NVM and the compensation file (issue 17): a loaded compensation
survives the safe state, a reconnect and a simulator restart; it compensates the damping drift
(checked on the World's true wave); `gyrobench fpga load/show` and their one-line errors."""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import json
import math
import tomllib

import numpy as np
import pytest
from cert_record import RECORD

from bench.analysis.slow_model import orbit_elements, state_from_elements
from bench.clock import SimClock
from bench.line.compensation import Coefficient, Compensation, CompensationError, from_record, from_runs, load
from bench.line.fpga_cli import load_trims
from drivers.fpga import FpgaLink
from drivers.fpga import protocol as p
from simulators.fpga import serve_fpga
from simulators.physics.params import preset
from simulators.probes import EndStateProbe
from simulators.world import World


def test_compensation_file_round_trips_with_uncertainties_and_provenance(tmp_path):
    comp = from_record(RECORD)
    # the narrower interval wins: hrg-damping's theta_tau (width 0.7) over hrg-free-decay's (width 4)
    assert comp.coefficients["theta_tau_deg"].value == 25.2 and comp.coefficients["theta_tau_deg"].run_id == "r-damp"
    c = comp.coefficients["delta_inv_tau_per_s"]
    assert c.u_low == pytest.approx(0.2e-5) and c.u_high == pytest.approx(0.3e-5)  # asymmetric: each side
    assert comp.coefficients["theta_w_deg"].u_low is None  # no interval: no U
    assert "tau_s" not in comp.coefficients  # not a trim
    assert comp.source_runs == ["r-damp", "r-fd"] and comp.serial == "HRG-2611-0042"
    path = comp.write(tmp_path / "comp.toml")
    doc = tomllib.loads(path.read_text())
    assert doc["coefficients"]["split_hz"] == {"value": 0.0049, "unit": "Hz", "u_low": pytest.approx(0.0002),
                                               "u_high": pytest.approx(0.0003), "register": "TRIM_SPLIT_HZ",
                                               "run_id": "r-fd", "procedure": "hrg-free-decay",
                                               "basis": "narrowest 95 % interval: hrg-free-decay width 0.0005"}
    back = load(path)
    assert back.coefficients == comp.coefficients and back.date == "2026-11-23T20:40:00+00:00"
    trims = back.trims()
    assert trims["TRIM_EN"] == p.TRIM_DRIFT | p.TRIM_SPLIT
    assert trims["TRIM_DRIFT_D_PER_S"] == 9.1e-5 and trims["TRIM_SPLIT_THETA_DEG"] == 10.3
    assert 0 < trims["TRIM_FILE_ID"] < 2**48


def test_from_runs_takes_the_store_rows():
    runs = [{"run_id": "r1", "procedure": "hrg-damping", "software_version": "0.1.0", "measurements": [
        {"name": "delta_inv_tau_per_s", "value": 1e-4, "unit": "1/s", "ci95_low": 0.9e-4, "ci95_high": 1.1e-4},
        {"name": "theta_tau_deg", "value": 12.0, "unit": "deg", "ci95_low": None, "ci95_high": None}]}]
    comp = from_runs("U1", runs)
    assert comp.software_version == "0.1.0" and comp.source_runs == ["r1"]
    assert comp.coefficients["delta_inv_tau_per_s"].u_high == pytest.approx(1e-5)


def test_out_of_range_and_bad_files_give_one_message(tmp_path):
    comp = Compensation("U1", {"split_hz": Coefficient("split_hz", 12.5, "Hz")})
    with pytest.raises(CompensationError) as err:
        comp.trims()
    assert str(err.value) == "compensation: split_hz=12.5 Hz is above the limit 10 of TRIM_SPLIT_HZ"
    bad = tmp_path / "bad.toml"
    bad.write_text('schema = "gyrobench-compensation/1"\nserial = "U1"\n[coefficients.theta_tau_deg]\nvalue = 1.0\n'
                   'unit = "rad"\n')
    with pytest.raises(CompensationError, match=r"theta_tau_deg in 'rad', expected 'deg'"):
        load(bad)
    with pytest.raises(CompensationError, match="not found"):
        load(tmp_path / "none.toml")


def _link(server, clock=None) -> FpgaLink:
    return FpgaLink(server.url, clock=clock, timeout_s=2.0).connect()


def test_trims_survive_safe_state_reconnect_and_restart(tmp_path):
    world = World(preset("hrg"), seed=1)
    server = serve_fpga(world)
    trims = from_record(RECORD).trims()
    link = _link(server)
    try:
        out = load_trims(link, trims)
        assert out["nvm"]["valid"] and out["nvm"]["match"] and out["nvm"]["commits"] == 1
        link.set_whole_angle(True)
        link.set_drift_compensation(True, 1e-3, 5.0)  # the bench's own compensation, then the safe state
        assert link.safe_state()
        assert link.read_trims() == {**link.read_trims(), **trims}
        link.close()
        link = _link(server)  # reconnect
        assert all(link.read_register(n) == v for n, v in trims.items())
    finally:
        link.close()
        server.stop()
    server = serve_fpga(world)  # simulator restart on the same World: power-up reads NVM
    link = _link(server)
    try:
        assert all(link.read_register(n) == v for n, v in trims.items())
        assert link.nvm_status()["match"]
        link.write_register("TRIM_EN", 0)  # RAM only: NVM keeps the block, reload restores it
        assert not link.nvm_status()["match"]
        link.reload_trims()
        assert link.read_register("TRIM_EN") == trims["TRIM_EN"]
        link.write_register("NVM_CMD", p.NVM_ERASE)
        assert link.nvm_status() == {"valid": False, "match": False, "crc_bad": False, "crc": 0, "commits": 1}
    finally:
        link.close()
        server.stop()


def test_corrupted_nvm_powers_up_untrimmed():
    world = World(preset("hrg"), seed=1)
    server = serve_fpga(world)
    with _link(server) as link:
        load_trims(link, from_record(RECORD).trims())
    server.stop()
    nvm = server.firmware.nvm
    nvm.data = bytes([nvm.data[0] ^ 0x10]) + nvm.data[1:]  # a flipped bit in the stored block
    server = serve_fpga(world)
    try:
        with _link(server) as link:
            st = link.nvm_status()
            assert st["crc_bad"] and not st["valid"]
            assert link.read_register("TRIM_EN") == 0 and link.read_register("TRIM_DRIFT_D_PER_S") == 0.0
    finally:
        server.stop()


def _drift_dps(trims: dict | None) -> float:
    """Whole-angle mode, no command, the wave 22.5 deg off the damping axis: its true drift rate
    (deg/s) over 40 s, with the trims loaded (and a safe state and reconnect between) or without."""
    params = preset("hrg")
    world = World(params, seed=3)
    world.resonator.set_state(state_from_elements(1.0, 0.0, math.radians(params.theta_tau_deg + 22.5)))
    clock = SimClock(world)
    server = serve_fpga(world, seed=4)
    link = _link(server, clock)
    try:
        if trims is not None:
            load_trims(link, trims)
            assert link.safe_state()
            link.close()
            link = _link(server, clock)
        link.write_register("LOOP_PERIOD_S", 0.05)
        link.set_pll(True, params.f0_hz)
        link.set_agc(True, 1.0)
        link.set_quadrature_loop(True)
        link.set_whole_angle(True, 0.0)  # DRIFT_COMP_EN stays clear: only the trims compensate
        link.set_drive_enabled(True)
        clock.sleep(10.0)
        tap = EndStateProbe()
        world.attach(tap)
        clock.sleep(40.0)
        theta = np.unwrap(4.0 * orbit_elements(np.array(tap.q))["theta_rad"]) / 4.0
        return math.degrees(np.polyfit(np.array(tap.t_s), theta, 1)[0])
    finally:
        link.close()
        server.stop()
        clock.close()


def test_loaded_drift_trims_cancel_the_damping_drift():
    """The truth's (D, theta_tau) loaded as trims: the drift D/4 (0.00229 deg/s) falls under 5 %."""
    truth = preset("hrg")
    d_dps = math.degrees(truth.delta_inv_tau_per_s / 4)
    comp = Compensation("U1", {
        "delta_inv_tau_per_s": Coefficient("delta_inv_tau_per_s", truth.delta_inv_tau_per_s, "1/s"),
        "theta_tau_deg": Coefficient("theta_tau_deg", truth.theta_tau_deg, "deg")})  # fmt: skip
    assert _drift_dps(None) == pytest.approx(d_dps, rel=0.1)
    assert abs(_drift_dps(comp.trims())) < 0.05 * d_dps


def test_split_trim_seeds_the_quadrature_observer():
    """With the split trim on, the observer starts at the true split (in its k/a pumping units)
    instead of zero: (Dw/2)(-sin 4 theta_w, cos 4 theta_w)."""
    from simulators.fpga import kernels as k
    from simulators.fpga.firmware import FpgaFirmware

    truth = preset("hrg")
    fw = FpgaFirmware(World(truth, seed=1))
    for name, value in (("TRIM_SPLIT_HZ", truth.split_hz), ("TRIM_SPLIT_THETA_DEG", truth.theta_w_deg),
                        ("TRIM_EN", p.TRIM_SPLIT)):
        fw.write(p.BY_NAME[name], value)
    fw.write(p.BY_NAME["CTRL_SET"], p.QUAD_EN)
    half_dw, th4 = math.pi * truth.split_hz, 4 * math.radians(truth.theta_w_deg)
    assert fw._st[k.S_H_C] == pytest.approx(-half_dw * math.sin(th4), rel=1e-3)
    assert fw._st[k.S_H_S] == pytest.approx(half_dw * math.cos(th4), rel=1e-3)


def test_cli_load_then_show_in_a_new_session(tmp_path, capsys):
    from bench.cli import main

    station = tmp_path / "st.toml"
    text = open("bench/stations/sim-hrg.toml").read().replace('id = "sim-hrg"', 'id = "nvm-hrg"')
    station.write_text(text + f'nvm_file = "{tmp_path / "fpga.nvm"}"\n')
    comp = from_record(RECORD).write(tmp_path / "comp.toml")
    runs = ["--runs-dir", str(tmp_path / "runs"), "--override-reason", "a bench test of the NVM"]
    assert main(["fpga", "load", str(comp), "--station", str(station), "--json", *runs]) == 0
    loaded = json.loads(capsys.readouterr().out)
    assert loaded["nvm"]["valid"] and loaded["serial"] == "HRG-2611-0042"
    assert main(["fpga", "show", "--station", str(station), "--json"]) == 0  # a new World: NVM from the file
    shown = json.loads(capsys.readouterr().out)
    assert shown["trims"] == loaded["trims"] and shown["nvm"]["match"]
    bad = tmp_path / "bad.toml"
    bad.write_text(comp.read_text().replace("value = 0.0049", "value = 11.0"))
    assert main(["fpga", "load", str(bad), "--station", str(station), *runs]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"gyrobench: error: {bad}: compensation: split_hz=11 Hz is above the limit 10 of TRIM_SPLIT_HZ"]


def test_an_identification_on_a_trimmed_unit_runs_untrimmed_and_restores_the_trims():
    """A retest: the HRG procedures' loop start writes TRIM_EN = 0 (RAM) and defers the NVM reload."""
    import logging
    from types import SimpleNamespace

    from procedures.hrg_excitation import HrgExcitation

    world = World(preset("hrg"), seed=1)
    server = serve_fpga(world)
    link = _link(server)
    deferred = []
    try:
        trims = from_record(RECORD).trims()
        load_trims(link, trims)
        ctx = SimpleNamespace(devices=SimpleNamespace(fpga=link), defer=lambda fn, what="": deferred.append(fn),
                              log=logging.getLogger("test"), subscribe=lambda device, callback: None)
        proc = HrgExcitation()
        proc.amplitude = 1.0
        proc._start_loops(ctx)
        assert link.read_register("TRIM_EN") == 0 and len(deferred) == 1
        assert link.nvm_status()["valid"] and not link.nvm_status()["match"]
        deferred[0]()
        assert link.read_register("TRIM_EN") == trims["TRIM_EN"] and link.nvm_status()["match"]
        link.safe_state()
    finally:
        link.close()
        server.stop()


def test_a_trim_read_back_unequal_is_one_message_naming_both_values():
    from bench.line.fpga_cli import TrimMismatch

    class Flaky:
        def write_trims(self, values):
            self.values = dict(values)

        def commit_trims(self):
            return 0x1234

        def reload_trims(self):
            pass

        def read_trims(self):
            return {**self.values, "TRIM_SPLIT_HZ": 0.0}  # a register the NVM did not keep

        def nvm_status(self):
            return {}

    with pytest.raises(TrimMismatch) as err:
        load_trims(Flaky(), from_record(RECORD).trims())
    assert str(err.value) == "TRIM_SPLIT_HZ read back 0.0 after the NVM commit, written 0.0049"


def test_cli_load_on_a_station_without_fpga_says_so(tmp_path, capsys):
    from bench.cli import main

    comp = from_record(RECORD).write(tmp_path / "comp.toml")
    text = open("bench/stations/sim-hrg.toml").read()
    station = tmp_path / "nofpga.toml"
    station.write_text(text[: text.index("[devices.fpga]")].replace('id = "sim-hrg"', 'id = "no-fpga"'))
    assert main(["fpga", "load", str(comp), "--station", str(station)]) == 2
    assert capsys.readouterr().err.strip() == (
        "gyrobench: error: station 'no-fpga' has no FPGA ([devices.fpga]) to hold trims; it has: frontend, table")


def test_gain_trims_scale_the_pickoffs_the_loops_and_stream_see():
    """TRIM_GAIN with TRIM_GAIN_X = 1.25: the streamed x pickoff is 1.25 x the untrimmed one (a
    free decay of tau 300 s moves it 3e-4 over the 0.1 s between the two records); y stays."""
    world = World(preset("hrg-ideal"), seed=1)
    world.resonator.set_state(state_from_elements(1.0, 0.2, math.radians(30.0)))
    clock = SimClock(world)
    server = serve_fpga(world)
    link = _link(server, clock)
    blocks: list[np.ndarray] = []
    link.subscribe(blocks.append)
    try:
        link.start_stream(10)
        clock.sleep(0.05)
        link.sync()
        before = np.vstack(blocks)[-1]
        link.write_trims({"TRIM_GAIN_X": 1.25, "TRIM_EN": p.TRIM_GAIN})
        clock.sleep(0.05)
        link.sync()
        after = np.vstack(blocks)[-1]
        link.stop_stream()
    finally:
        link.close()
        server.stop()
        clock.close()
    cx, sx, cy, sy = (p.STREAM_COLUMNS.index(c) for c in ("cx", "sx", "cy", "sy"))
    x0, x1 = math.hypot(before[cx], before[sx]), math.hypot(after[cx], after[sx])
    y0, y1 = math.hypot(before[cy], before[sy]), math.hypot(after[cy], after[sy])
    assert x0 > 0.3 and y0 > 0.3
    assert x1 / x0 == pytest.approx(1.25, rel=1e-3) and y1 / y0 == pytest.approx(1.0, rel=1e-3)


def _learning_drift_rms_dph(split_trim: bool) -> float:
    """Whole-angle at 2 deg/s from rest (5 mHz split, no damping anisotropy, no noise): rms of the
    true wave's rate error, output-referred, over seconds 2-12 while the observer learns the split."""
    from simulators.fpga.firmware import FpgaFirmware

    params = preset("hrg", delta_inv_tau_per_s=0.0, noise_sigma=0.0)
    world = World(params, seed=1)
    world.resonator.set_state(state_from_elements(1.0, 0.0, 0.0))
    fw = FpgaFirmware(world)
    world.attach(fw)
    regs = [("REF_FREQ_HZ", params.f0_hz), ("AGC_SETPOINT", 1.0), ("PRECESSION_RATE_DPS", 2.0)]
    if split_trim:
        regs += [("TRIM_SPLIT_HZ", params.split_hz), ("TRIM_SPLIT_THETA_DEG", params.theta_w_deg),
                 ("TRIM_EN", p.TRIM_SPLIT)]
    for name, value in regs:
        fw.write(p.BY_NAME[name], value)
    fw.write(p.BY_NAME["CTRL"], p.DRIVE_EN | p.AGC_EN | p.PLL_EN | p.QUAD_EN | p.WHOLE_ANGLE)
    world.advance(2.0)
    tap = EndStateProbe()
    world.attach(tap)
    world.advance(10.0)
    t_s = np.array(tap.t_s)
    theta = np.unwrap(4.0 * orbit_elements(np.array(tap.q))["theta_rad"]) / 4.0
    err_dph = (np.degrees(np.gradient(theta, t_s)) - 2.0) * 3600 / params.bryan_factor
    return float(np.sqrt(np.mean(err_dph**2)))


def test_split_trim_removes_the_observers_learning_drift():
    """Untrimmed, the wave drifts ~7.6 deg/h rms while the observer learns the split; with the split
    trim it starts from it: ~1.1 deg/h."""
    without, with_trim = _learning_drift_rms_dph(False), _learning_drift_rms_dph(True)
    assert without > 5.0 and with_trim < 0.25 * without, (without, with_trim)


def test_the_scale_factor_coefficients_load_the_thermal_trim():
    """thermal_sf_ppm and thermal_sf_ppm_per_hz go to TRIM_SF_PPM, TRIM_SF_PPM_PER_HZ and switch
    TRIM_THERMAL on, alone or with the bias pair; out of the register's range is one message."""
    sf = {"thermal_sf_ppm": Coefficient("thermal_sf_ppm", -13000.0, "ppm"),
          "thermal_sf_ppm_per_hz": Coefficient("thermal_sf_ppm_per_hz", -107.0, "ppm/Hz")}
    trims = Compensation("U1", dict(sf)).trims()
    assert trims["TRIM_EN"] == p.TRIM_THERMAL
    assert trims["TRIM_SF_PPM"] == -13000.0 and trims["TRIM_SF_PPM_PER_HZ"] == -107.0
    bias = {"thermal_bias_dph": Coefficient("thermal_bias_dph", 150.0, "deg/h"),
            "thermal_bias_dph_per_hz": Coefficient("thermal_bias_dph_per_hz", -0.5, "deg/h/Hz")}
    assert Compensation("U1", {**sf, **bias}).trims()["TRIM_EN"] == p.TRIM_THERMAL
    with pytest.raises(CompensationError, match="above the limit 100000 of TRIM_SF_PPM"):
        Compensation("U1", {**sf, "thermal_sf_ppm": Coefficient("thermal_sf_ppm", 2e5, "ppm")}).trims()
