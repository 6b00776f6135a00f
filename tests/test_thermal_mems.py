"""The MEMS ring in the chamber (#34): its bias follows temperature by the datasheet-sized
coefficients of simulators.physics.errors (docs/chamber.md, "The MEMS ring in the chamber"), and the
line's eol-mems-thermal (thermal-ramp with rotate-and-static, the thermal trim verified, the trim
into NVM) passes on sim-mems-thermal; sim-mems-thermal-4 takes the sequence as a batch."""

from __future__ import annotations

import json
import math

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


def test_the_package_stress_plays_behind_the_temperature():
    """Thermal hysteresis (docs/chamber.md, "Thermal hysteresis"): the stress state follows the
    temperature through a play of +-hyst_halfwidth_k, so at one temperature the bias on a heating
    branch and on a cooling one differ by bias_hyst_dps (and the scale factor by sf_hyst_ppm),
    settled or not; a unit that never left its start temperature is on no branch."""
    from simulators.physics.params import PRESETS
    from simulators.world import World

    mems = ERROR_PRESETS["mems-realistic"]
    assert mems.hysteretic and mems.hyst_halfwidth_k == 0.5 and mems.bias_hyst_dps == -0.06
    world = World(PRESETS["mems-realistic"], seed=1, errors=mems)
    assert world.truth()["hysteresis_state"] == 0.0 and world.truth()["thermal_bias_dps"] == 0.0
    for t_c in (26.0, 28.0, 30.0):  # heating
        world.set_temperature(t_c)
    heating = world.truth()
    assert world.stress_c == 29.5 and heating["hysteresis_state"] == 1.0
    world.set_temperature(29.8)  # within the play: the stress stays
    assert world.stress_c == 29.5
    for t_c in (35.0, 32.0, 30.0):  # over the top and back down to 30
        world.set_temperature(t_c)
    cooling = world.truth()
    assert world.stress_c == 30.5 and cooling["hysteresis_state"] == -1.0
    assert heating["thermal_bias_dps"] - cooling["thermal_bias_dps"] == pytest.approx(-0.06)
    sf = {k: 1.0 / v["pickoff_gain_x"] for k, v in (("h", heating), ("c", cooling))}  # FTR's SF ~ 1 / gain
    assert (sf["h"] - sf["c"]) / sf["c"] * 1e6 == pytest.approx(-200.0, rel=1e-3)
    assert ErrorSources(bias_tc_dps_k=0.03).thermal_bias_dps(30.0, 29.0) == pytest.approx(0.15)  # no hysteresis
    with pytest.raises(ValueError, match="hyst_halfwidth_k"):
        ErrorSources(bias_hyst_dps=0.1)
    hrg = World(PRESETS["hrg"], seed=1, errors=ERROR_PRESETS["hrg-realistic"])
    hrg.set_temperature(40.0)
    assert hrg.stress_c == 25.0 and "package_stress_c" not in hrg.truth()  # off outside the MEMS preset


def test_the_ramp_measures_the_hysteresis_against_its_truth(tmp_path, capsys):
    """thermal-ramp on the MEMS ring (seed 0, 25..29 degC at 4 degC/min, 5 s segments at rest, 60 s
    tails): bias_hysteresis_dph, fitted beside the bias that the frequency's rate adds, holds the
    unit's -0.06 deg/s (-216 deg/h) within its interval; so does verify_hysteresis_dph, the
    verification point at 27 degC settled from below and from above (20 s records), in an interval
    several times narrower (no rate term to separate)."""
    from pathlib import Path

    from bench.cli import main

    station = tmp_path / "st.toml"
    station.write_text(Path("bench/stations/sim-mems-thermal.toml").read_text()
                       .replace('id = "sim-mems-thermal"', 'id = "mems-hyst-test"')
                       .replace("case_tau_s = 60.0", "case_tau_s = 15.0"))
    sets = {"t_low_degc": 25, "t_high_degc": 29, "cycle_degc_per_min": 4, "segment_s": 5, "rate_dps": 0,
            "tail_s": 60, "settle_window_s": 5, "settle_ppm_per_min": 6, "verify_points": 1, "record_s": 20,
            "verify_both_branches": "true", "stream_hz": 10}
    args = ["run", "thermal-ramp", "--station", str(station), "--seed", "0", "--json",
            "--runs-dir", str(tmp_path / "runs"), "--results", str(tmp_path / "r.sqlite")]
    for k, v in sets.items():
        args += ["--set", f"{k}={v}"]
    assert main(args) == 0
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    truth_dph = out["truth"]["err_bias_hyst_dps"] * 3600.0
    assert truth_dph == pytest.approx(-216.0)
    m = out["measurements"]["bias_hysteresis_dph"]
    lo, hi = m["ci95"]
    assert lo <= truth_dph <= hi, m
    assert hi - lo < 3000.0  # a measurement, if a coarse one on 4 K of ramp
    v = out["measurements"]["verify_hysteresis_dph"]
    assert v["ci95"][0] <= truth_dph <= v["ci95"][1], v
    assert v["ci95"][1] - v["ci95"][0] < 0.5 * (hi - lo)


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
    f25 = m["f0_at_25c_hz"]  # the PLL's frequency, 2.41 Hz under f0 + freq_offset (docs/chamber.md)
    assert f25["interval"][0] <= f25["truth"] <= f25["interval"][1], f25
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
    assert back["TRIM_SF_PPM"] == pytest.approx(m["thermal_sf_ppm"]["value"], rel=1e-6)  # the scale factor trim too
    assert back["TRIM_SF_PPM_PER_HZ"] == pytest.approx(m["thermal_sf_ppm_per_hz"]["value"], rel=1e-6)
    # the branch-aware trim (hyst_halfwidth_degc 0.5 in the sequence): the play's half-width is 0.5 K through the
    # ring's df/dT (-0.41 Hz/K), the gaps the ramp's hysteresis fit; into NVM with the rest
    assert m["thermal_hyst_hz"]["value"] == pytest.approx(0.5 * tc["value"] * 1e-6 * f25["value"], rel=0.01)
    assert back["TRIM_HYST_HZ"] == pytest.approx(m["thermal_hyst_hz"]["value"], rel=1e-6)
    assert back["TRIM_BIAS_HYST_DPH"] == pytest.approx(m["thermal_bias_hyst_dph"]["value"], rel=1e-6)
    assert back["TRIM_SF_HYST_PPM"] == 0.0  # hyst_sf_trim off: the ramp's scale factor gap is noise (+-15 000 ppm)
    assert m["verify_residual_hyst_dph"]["value"] < 4.0 * m["verify_noise_dph"]["value"]
    # the verification's +-10 deg/s pair through the trimmed output: ~0.35 % left (noise ~0.22 %), 2.2 % untrimmed
    assert m["verify_sf_error_ppm"]["value"] < 3.0 * m["verify_sf_noise_ppm"]["value"]
    assert m["verify_sf_error_raw_ppm"]["value"] > 3.0 * m["verify_sf_error_ppm"]["value"]
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


def test_the_branch_aware_trim_leaves_less_at_the_verification(tmp_path, capsys):
    """thermal-ramp on the MEMS ring (seed 0, 25..31 degC at 4 degC/min, 5 s segments at rest, 60 s tails) with
    the branch-aware trim (a 0.5 K play through the ring's df/dT, the hysteresis fitted without the rate term)
    in the FPGA, verified at 26.5 and 29.5 degC settled from below and from above (60 s records): the single-valued
    trim leaves the hysteresis's half at each point (145 deg/h rms against a noise of 39), the branch-aware one
    81, within 1.2 of what the noise and the fits' intervals allow (`verify_allowed_dph` 73.6: the records'
    noise, the trim line's standard error at each point and the gap's over 2; 1.10 here)."""
    from pathlib import Path

    from bench.cli import main

    station = tmp_path / "st.toml"
    station.write_text(Path("bench/stations/sim-mems-thermal.toml").read_text()
                       .replace('id = "sim-mems-thermal"', 'id = "mems-hyst-trim-test"')
                       .replace("case_tau_s = 60.0", "case_tau_s = 15.0"))
    sets = {"t_low_degc": 25, "t_high_degc": 31, "cycle_degc_per_min": 4, "segment_s": 5, "rate_dps": 0,
            "tail_s": 60, "settle_window_s": 5, "settle_ppm_per_min": 6, "verify_points": 2, "record_s": 60,
            "verify_both_branches": "true", "stream_hz": 10, "hyst_halfwidth_degc": 0.5, "hyst_rate_term": "false"}
    args = ["run", "thermal-ramp", "--station", str(station), "--seed", "0", "--json",
            "--runs-dir", str(tmp_path / "runs"), "--results", str(tmp_path / "r.sqlite")]
    for k, v in sets.items():
        args += ["--set", f"{k}={v}"]
    assert main(args) == 0
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    m = {k: v["value"] for k, v in out["measurements"].items()}
    gap = out["measurements"]["bias_hysteresis_dph"]
    assert gap["ci95"][0] <= -216.0 <= gap["ci95"][1]  # the unit's -0.06 deg/s
    assert m["thermal_hyst_hz"] == pytest.approx(0.5 * -30e-6 * 13647.0, rel=0.02)  # 0.5 K through -0.41 Hz/K
    before, after, noise = m["verify_residual_dph"], m["verify_residual_hyst_dph"], m["verify_noise_dph"]
    assert after < 0.6 * before
    allowed = m["verify_allowed_dph"]
    # at least the noise and the gap's standard error over 2 (the play's state is at most 1), the trim line's on top
    assert allowed > 0.95 * math.hypot(noise, 0.5 * (gap["ci95"][1] - gap["ci95"][0]) / (2 * 1.96))
    assert after < 1.2 * allowed, (after, allowed)
