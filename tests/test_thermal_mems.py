"""The MEMS ring in the chamber (#34): its bias follows temperature by the datasheet-sized
coefficients of simulators.physics.errors (docs/chamber.md, "The MEMS ring in the chamber"), and the
line's eol-mems-thermal (thermal-ramp with rotate-and-static, the thermal trim verified, the trim
into NVM) passes on sim-mems-thermal; sim-mems-thermal-4 takes the sequence as a batch."""

from __future__ import annotations

import json

import pytest

from simulators.physics.errors import ERROR_PRESETS, ErrorSources


def test_the_thermal_bias_follows_the_declared_coefficients():
    e = ErrorSources(bias_tc_dps_k=0.03, bias_tc2_dps_k2=5e-5)
    assert e.thermal_bias_dps(25.0) == 0.0
    assert e.thermal_bias_dps(85.0) == pytest.approx(0.03 * 60 + 5e-5 * 3600)  # 1.98 deg/s
    assert e.thermal_bias_dps(-35.0) == pytest.approx(-0.03 * 60 + 5e-5 * 3600)
    mems = ERROR_PRESETS["mems-realistic"]
    assert 0.01 <= mems.bias_tc_dps_k <= 0.16  # the datasheets' range (docs/chamber.md)
    truth = mems.truth(0.0, 45.0, {"f0_hz": 13647.0, "freq_offset_hz": 0.0, "tau_s": 0.05, "q_factor": 2000.0,
                                   "Q": 2000.0, "gamma": 40.0, "c_m": 0.0})
    assert truth["thermal_bias_dps"] == pytest.approx(0.03 * 20 + 5e-5 * 400)
    assert ERROR_PRESETS["hrg-realistic"].thermal_bias_dps(85.0) == 0.0  # the HRG's bias moves by its physics only


#: the shipped sequence's parameters made shorter for a test (the ring's nonlinear averaged model
#: integrates each block with an adaptive solver: ~0.2 CPU s a simulated s, ten times the HRG's)
SHORTER = {"t_high_degc = 35.0": "t_high_degc = 29.0", "cycle_degc_per_min = 5.0": "cycle_degc_per_min = 8.0",
           "segment_s = 10.0": "segment_s = 5.0", "tail_s = 40.0": "tail_s = 15.0",
           "settle_window_s = 10.0": "settle_window_s = 5.0", "settle_ppm_per_min = 2.0": "settle_ppm_per_min = 6.0",
           "record_s = 30.0": "record_s = 15.0"}


def test_line_run_eol_mems_thermal_leaves_the_thermal_trim_in_nvm(tmp_path, capsys):
    """The ramp with +-10 deg/s pairs, the trim verified at 27 degC through the FPGA, then (PASS)
    the trim into the ring's NVM through the line's gated trims, read back (the shipped sequence and
    station, shortened: 25..29 degC, a package 15 s behind the air)."""
    from pathlib import Path

    from bench.cli import main

    station = tmp_path / "st.toml"
    station.write_text(Path("bench/stations/sim-mems-thermal.toml").read_text()
                       .replace('id = "sim-mems-thermal"', 'id = "mems-thermal-test"')
                       .replace("case_tau_s = 60.0", "case_tau_s = 15.0"))
    seq = Path("bench/line/sequences/eol-mems-thermal.toml").read_text()
    for old, new in SHORTER.items():
        assert old in seq
        seq = seq.replace(old, new)
    (tmp_path / "seq.toml").write_text(seq)
    code = main(["line", "run", str(tmp_path / "seq.toml"), "--station", str(station), "--operator", "ada", "--dut",
                 "MEMS-000777", "--yes", "--lot", "L1", "--runs-dir", str(tmp_path / "runs"), "--json"])
    (rec,) = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert code == 0 and rec["outcome"] == "PASS", rec["summary"]
    m = {x["name"]: x for x in rec["measurements"]}
    tc = m["f0_tc_ppm_k"]
    assert tc["interval"][0] <= tc["truth"] == -30.0 <= tc["interval"][1]  # silicon's coefficient
    # the trim's slope against the ring's frequency, as a bias coefficient per kelvin: the unit's
    # own physics (about -0.07 deg/s/K through its damping) and the declared +0.03 deg/s/K together
    df_dt_hz_k = tc["value"] * 1e-6 * 13647.0
    bias_tc_dps_k = m["thermal_bias_dph_per_hz"]["value"] * df_dt_hz_k / 3600.0
    assert 0.01 <= abs(bias_tc_dps_k) <= 0.16, bias_tc_dps_k
    assert m["verify_residual_dph"]["value"] < 4.0 * m["verify_noise_dph"]["value"]
    back = rec["trims"]["read_back"]
    assert rec["trims"]["written"] and int(back["TRIM_EN"]) == 0x08
    assert back["TRIM_BIAS_DPH"] == pytest.approx(m["thermal_bias_dph"]["value"], rel=1e-6)  # tens of deg/s
    assert back["TRIM_BIAS_DPH_PER_HZ"] == pytest.approx(m["thermal_bias_dph_per_hz"]["value"], rel=1e-6)
    assert m["sf_at_25c"]["value"] == pytest.approx(1.0, abs=0.05)  # the rotate-and-static pairs' scale factor


def test_the_mems_sequence_runs_as_a_batch_on_the_four_slot_station():
    from bench.composition import load_station
    from bench.line.batch_run import check_batch_sequence
    from bench.line.limits import load_limits
    from bench.line.sequence import load_sequence
    from bench.station_config import load_config

    cfg = load_config("sim-mems-thermal-4")
    assert set(cfg.devices) == {"table", "chamber"} and sorted(cfg.slots) == [1, 2, 3, 4]
    seq = load_sequence("bench/line/sequences/eol-mems-thermal.toml")
    station = load_station("sim-mems-thermal-4", seed=0)
    try:
        check_batch_sequence(seq, load_limits("bench/line/limits/mems-thermal.toml"), station)
        f0 = [station.rig.worlds[k].params.f0_hz for k in range(4)]
    finally:
        station.close()
    assert len(set(f0)) == 4  # four rings drawn from the lot's spread
