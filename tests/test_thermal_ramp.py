"""thermal-ramp on the quick thermal HRG station: one heating and cooling cycle 25 -> 35 -> 25 degC;
the frequency coefficient against the simulator's truth, the resonator's lag behind the case
thermocouple seen in the heating-cooling gap, a verification record at 30 degC, and the
pure helpers against known numbers."""

from __future__ import annotations

import numpy as np
import pytest

from bench.analysis.thermal_fit import fit_temperature_polynomial
from bench.analysis.thermal_ramp import branch_gap, frequency_thermometer, trend_mean
from procedures.thermal_ramp import ThermalRamp


def test_trend_mean_takes_a_ramp_for_no_noise():
    rng = np.random.default_rng(1)
    v = np.linspace(0.0, 10.0, 1000) + rng.normal(0.0, 1.0, 1000)
    m, se = trend_mean(v, 10)
    assert m == pytest.approx(5.0, abs=0.2)
    assert 0.5 / np.sqrt(1000) < se < 3.0 / np.sqrt(1000)  # the noise's, not the ramp's 10/sqrt(12)


def test_branch_gap_finds_a_known_lag():
    """y = 2 (T - lag) on heating, 2 (T + lag) on cooling, lag 0.5: the gap is -2 and the lag 0.5."""
    rng = np.random.default_rng(2)
    t = np.tile(np.linspace(0.0, 50.0, 20), 2)
    heating = np.arange(40) < 20
    y = 2.0 * (t + np.where(heating, -0.5, 0.5)) + rng.normal(0.0, 0.01, 40)
    fit = fit_temperature_polynomial(t, y, np.full(40, 0.01), max_order=1, min_order=1)
    g = branch_gap(fit, heating, 2.0)
    assert g.gap == pytest.approx(-2.0, abs=0.02) and g.lag_ci95_c[0] <= 0.5 <= g.lag_ci95_c[1]
    tf, _, line = frequency_thermometer(y, np.full(40, 0.01), t)
    assert line.coeffs[1] == pytest.approx(2.0, rel=1e-3) and np.allclose(tf, y / 2.0, atol=0.01)


@pytest.mark.parametrize("sim_station", ["sim-hrg-thermal-quick"], indirect=True)
def test_ramp_cycle_finds_the_coefficient_and_the_lag(run_procedure, sim_station):
    params = {"t_low_degc": 25.0, "t_high_degc": 35.0, "cycle_degc_per_min": 5.0, "segment_s": 20.0,
              "tail_s": 60.0, "settle_window_s": 20.0, "settle_ppm_per_min": 1.0, "max_order": 2,
              "verify_points": 1, "record_s": 60.0, "rate_dps": 10.0}
    record = run_procedure(ThermalRamp, params)
    assert record.outcome == "COMPLETE", (record.end_reason, record.traceback)
    got = {m.name: m for m in record.measurements}
    print({k: (m.value, m.ci95) for k, m in got.items()})
    truth = sim_station.truth()
    tc = got["f0_tc_ppm_k"]
    assert tc.ci95[0] <= truth["err_freq_tc_ppm_k"] <= tc.ci95[1], (tc.value, tc.ci95)
    assert tc.value == pytest.approx(truth["err_freq_tc_ppm_k"], rel=0.1)  # 52.7: the short cycle's lags
    lag = got["part_lag_degc"]
    assert lag.ci95[0] > 0.0  # the resonator trails the case thermocouple (20 s behind it)
    # against the part thermocouple the frequency keeps that lag as its residual (slope x lag);
    # read as a thermometer it has none of its own: the bias fits against part and frequency agree
    slope_hz_k = tc.value * 1e-6 * got["f0_at_25c_hz"].value
    assert got["f0_rms_part_hz"].value == pytest.approx(slope_hz_k * lag.value, rel=0.3)
    # the scale factor from the +-10 deg/s pairs: its coefficient is the pickoff gains' (-30 ppm/K)
    sf_tc, sf_truth = got["sf_tc_ppm_k"], ThermalRamp.truth_for(truth)
    assert sf_tc.ci95[0] <= sf_truth["sf_tc_ppm_k"] == -30.0 <= sf_tc.ci95[1], (sf_tc.value, sf_tc.ci95)
    print("sf truth", sf_truth.get("sf_at_25c"))
    assert got["cycle_s"].value < 450.0  # 2 x (2 min ramp + 1 min tail) and the table's rate changes
    # the verification at 30 degC, settled, with the thermal trim in the FPGA: the unit's own output
    # shows the bias (153 deg/h untrimmed) within 3 of its record's noise (the trim's interval adds to it)
    assert got["thermal_bias_dph"].ci95[0] < 160.0 < got["thermal_bias_dph"].ci95[1] + 10.0
    assert got["verify_residual_dph"].value < 3.0 * got["verify_noise_dph"].value + 0.5
    # the scale factor trim from the pairs (-1.0 % against the nominal G K = 3.6 x 0.277 = 0.9972 the run
    # records, 0.987 / 0.9972 - 1, at REF_FREQ_HZ, -107 ppm/Hz:
    # the gains' -30 ppm/K over the frequency's +0.29 Hz/K): the verification's +-10 deg/s pair at 30 degC
    # through the FPGA's trimmed output is within 3 of its noise (~15 ppm); untrimmed it is off by ~1.0 %
    assert got["thermal_sf_ppm"].value == pytest.approx(1e6 * (0.987 / 0.9972 - 1.0), abs=500.0)
    assert got["verify_sf_error_ppm"].value < 3.0 * got["verify_sf_noise_ppm"].value
    assert got["verify_sf_error_raw_ppm"].value == pytest.approx(abs(got["thermal_sf_ppm"].value), rel=0.05)
    from bench.recorder import open_run

    data = open_run(record.raw_file)
    figs = ThermalRamp(record.params).figures(data)
    assert [f.key for f in figs] == ["thermal-ramp_temperatures", "thermal-ramp_fits"]
    vt = data.table("thermal_ramp_verify")
    assert vt["trim_bias_dph"][0] == pytest.approx(got["thermal_bias_dph"].value, rel=1e-9)
    fpga = sim_station.devices["fpga"]
    assert fpga.read_register("TRIM_EN") == 0 and fpga.read_register("TRIM_BIAS_DPH") == 0.0  # restored
    assert fpga.read_register("TRIM_SF_PPM") == fpga.read_register("TRIM_SF_PPM_PER_HZ") == 0.0
    vs = data.table("thermal_ramp_verify_sf")
    assert list(vs["rate_dps"]) == [10.0, -10.0]
    assert vs["trim_sf_ppm"][0] == pytest.approx(got["thermal_sf_ppm"].value, rel=1e-9)
    assert sim_station.devices["chamber"].setpoint_c() == 25.0
    # the branches ran as ramp-rate profiles on the controller, each deleted after its branch
    assert any("on the chamber's controller" in r["msg"] for r in data.log())
    assert sim_station.devices["chamber"].supports_profiles() and sim_station.devices["chamber"].ramp_profile is None
    from drivers.chamber import watlow_f4_protocol as fp

    assert sim_station.devices["chamber"]._read(fp.HR_STEPS_AVAILABLE)[0] == 256


@pytest.mark.parametrize("sim_station", ["sim-hrg-thermal-quick"], indirect=True)
def test_without_the_controllers_ramp_the_pc_steps_the_set_point(run_procedure, sim_station):
    """controller_ramp off: the set point written from the PC with the ramp limit, as before; the
    cycle takes the same time (the air at 5 deg/min either way, 2 x (24 s + 5 s tail) and segments)."""
    params = {"t_low_degc": 24.0, "t_high_degc": 26.0, "cycle_degc_per_min": 5.0, "segment_s": 5.0, "tail_s": 5.0,
              "settle_window_s": 10.0, "settle_ppm_per_min": 1.0, "max_order": 1, "controller_ramp": False}
    record = run_procedure(ThermalRamp, params)
    assert record.outcome == "COMPLETE", (record.end_reason, record.traceback)
    from bench.recorder import open_run

    data = open_run(record.raw_file)
    assert any("from the PC" in r["msg"] for r in data.log())
    ch = data.table("chamber")
    assert max(ch["air_degc"]) == pytest.approx(26.0) and sim_station.devices["chamber"].ramp_rate_c_per_min() == 5.0
    assert {m.name: m.value for m in record.measurements}["cycle_s"] < 90.0


def test_the_resonator_trails_the_case_by_its_time_constant():
    """A steady air ramp r: the case trails the air by r tau_case, the resonator the case by r tau_res."""
    from simulators.chamber.thermal import ChamberThermal

    th = ChamberThermal(setpoint_c=100.0, ramp_c_per_min=6.0, case_tau_s=60.0, resonator_tau_s=20.0)
    for _ in range(6000):  # 600 s in 0.1 s blocks: both lags in their steady state
        th.step(0.1)
    r = 0.1  # degC/s
    assert th.air_c - th.case_c == pytest.approx(r * 60.0, rel=1e-3)
    assert th.case_c - th.resonator_c == pytest.approx(r * 20.0, rel=1e-3)


def test_line_run_eol_hrg_thermal_leaves_the_thermal_trim_in_nvm(tmp_path, capsys):
    """The line's sequence: the ramp, the trim verified at 30 degC through the FPGA, then (PASS) the
    thermal trim into the unit's NVM through the line's gated trims, read back."""
    import json

    from bench.cli import main
    from bench.line.compensation import unit_id

    station = tmp_path / "st.toml"
    text = open("bench/stations/sim-hrg-thermal-quick.toml").read()
    station.write_text(text.replace('id = "sim-hrg-thermal-quick"', 'id = "nvm-thermal"')
                       + f'nvm_file = "{tmp_path / "fpga.nvm"}"\n')
    code = main(["line", "run", "eol-hrg-thermal", "--station", str(station), "--operator", "ada", "--dut",
                 "HRG-000777", "--yes", "--lot", "L1", "--runs-dir", str(tmp_path / "runs"), "--json"])
    (rec,) = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert code == 0 and rec["outcome"] == "PASS", rec
    assert rec["trims"]["written"], rec["trims"]
    assert rec["trims"]["chosen"]["thermal_bias_dph"]["procedure"] == "thermal-ramp"
    back = rec["trims"]["read_back"]
    assert int(back["TRIM_EN"]) == 0x08 and int(back["TRIM_UNIT_ID"]) == unit_id("HRG-000777")
    m = {x["name"]: x["value"] for x in rec["measurements"]}
    assert back["TRIM_BIAS_DPH"] == pytest.approx(m["thermal_bias_dph"], rel=1e-12)
    assert back["TRIM_BIAS_DPH_PER_HZ"] == pytest.approx(m["thermal_bias_dph_per_hz"], rel=1e-12)
    assert back["TRIM_SF_PPM"] == pytest.approx(m["thermal_sf_ppm"], rel=1e-12)  # the scale factor trim (+-10 deg/s)
    assert back["TRIM_SF_PPM_PER_HZ"] == pytest.approx(m["thermal_sf_ppm_per_hz"], rel=1e-12)
    assert m["verify_sf_error_ppm"] < 3.0 * m["verify_sf_noise_ppm"]  # judged: <= 100 ppm


def test_a_turning_ramp_asks_the_table_for_its_rate():
    assert ThermalRamp().demands() == []
    d = ThermalRamp({"rate_dps": 20.0, "accel_dps2": 50.0}).demands()
    assert [(x.role, x.limit_key, x.value) for x in d] == [("table", "max_rate_dps", 20.0),
                                                           ("table", "max_accel_dps2", 50.0)]


def test_the_verification_measurements_are_expected_only_with_verification_points():
    """verify_residual_part_dph came out NOT MEASURED with no reason on every run without a
    verification (verify_points 0): like its siblings it is expected only with verify_points > 0."""
    for points, expected in ((0, False), (2, True)):
        proc = ThermalRamp({"verify_points": points})
        names = ("verify_residual_dph", "verify_residual_part_dph", "verify_noise_dph")
        applies = {m.name: m.applies(proc) for m in proc.measurements if m.name in names}
        assert len(applies) == 3 and set(applies.values()) == {expected}, applies


def test_branch_hysteresis_separates_the_gap_from_a_rate_term():
    """A cycle 25 -> 35 -> 25 whose rate regressor ramps up and down within each branch (the ramp's
    start and tail): y = 3 (T - 25) + 40 rate + gap s / 2 with gap -2; the fit finds the gap within its
    interval, where a branch mean (branch_gap) takes the rate term for hysteresis."""
    from bench.analysis.thermal_ramp import branch_hysteresis

    rng = np.random.default_rng(5)
    n = 30
    up = 25.0 + 10.0 * np.linspace(0.0, 1.0, n) ** 1.5
    t = np.concatenate([up, up[::-1]])
    heating = np.arange(2 * n) < n
    rate = np.concatenate([np.gradient(up), -np.gradient(up)[::-1]])
    y = 3.0 * (t - 25.0) + 40.0 * rate + np.where(heating, -1.0, 1.0) + rng.normal(0.0, 0.05, 2 * n)
    h = branch_hysteresis(t, y, np.full(2 * n, 0.05), heating, rate, order=1, guard_c=1.0)
    assert h.gap_ci95[0] <= -2.0 <= h.gap_ci95[1] and h.gap_ci95[1] - h.gap_ci95[0] < 0.5
    assert h.rate_coeff_ci95[0] <= 40.0 <= h.rate_coeff_ci95[1]
    assert h.n_used < 2 * n  # the points within 1 degC of each turning point are left out
    naive = fit_temperature_polynomial(t, y, np.full(2 * n, 0.05), max_order=1, min_order=1)
    assert abs(branch_gap(naive, heating, 3.0).gap - -2.0) > 1.0  # the rate term taken for hysteresis
    with pytest.raises(ValueError, match="guard"):
        branch_hysteresis(t, y, np.full(2 * n, 0.05), heating, rate, guard_c=20.0)


def test_branch_hysteresis_without_the_rate_term_is_narrower_where_there_is_none():
    """The same cycle with no rate term in y (a drive that does not trail): rate None fits the gap alone,
    its interval holding the truth -2 and narrower than the fit that also carries a rate coefficient."""
    from bench.analysis.thermal_ramp import branch_hysteresis

    rng = np.random.default_rng(6)
    n = 30
    up = 25.0 + 10.0 * np.linspace(0.0, 1.0, n) ** 1.5
    t = np.concatenate([up, up[::-1]])
    heating = np.arange(2 * n) < n
    rate = np.concatenate([np.gradient(up), -np.gradient(up)[::-1]])
    y = 3.0 * (t - 25.0) + np.where(heating, -1.0, 1.0) + rng.normal(0.0, 0.05, 2 * n)
    sigma = np.full(2 * n, 0.05)
    alone = branch_hysteresis(t, y, sigma, heating, None, order=1, guard_c=1.0)
    both = branch_hysteresis(t, y, sigma, heating, rate, order=1, guard_c=1.0)
    assert alone.gap_ci95[0] <= -2.0 <= alone.gap_ci95[1]
    assert alone.rate_coeff == 0.0 and alone.rate_coeff_ci95 == (0.0, 0.0) and alone.dof == both.dof + 1
    assert alone.gap_ci95[1] - alone.gap_ci95[0] < both.gap_ci95[1] - both.gap_ci95[0]
