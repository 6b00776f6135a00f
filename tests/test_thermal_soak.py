"""thermal-soak on the thermal HRG station (a quick chamber and a light case so the test is short):
3 set points, each settled from the resonator frequency's own drift; the frequency fit's
temperature coefficient against the simulator's truth, the bias fit, and the chamber back at
ambient."""

from __future__ import annotations

import json

import pytest

from bench.recorder import open_run
from procedures.thermal_soak import ThermalSoak


@pytest.mark.parametrize("sim_station", ["sim-hrg-thermal-quick"], indirect=True)
def test_soak_finds_the_frequency_temperature_coefficient(run_procedure, sim_station):
    params = {"t_low_degc": 15.0, "t_high_degc": 35.0, "points": 3, "ramp_degc_per_min": 30.0, "settle_window_s": 30.0,
              "settle_ppm_per_min": 0.2, "record_s": 60.0, "max_order": 2}
    record = run_procedure(ThermalSoak, params)
    assert record.outcome == "COMPLETE", (record.end_reason, record.traceback)
    got = {m.name: m for m in record.measurements}
    truth = sim_station.truth()
    tc = got["f0_tc_ppm_k"]
    print({k: (m.value, m.ci95) for k, m in got.items()})
    assert tc.ci95[0] <= truth["err_freq_tc_ppm_k"] <= tc.ci95[1], (tc.value, tc.ci95)
    assert tc.value == pytest.approx(truth["err_freq_tc_ppm_k"], rel=0.02)
    assert got["f0_fit_order"].value == 1.0
    f25, f25_true = got["f0_at_25c_hz"], ThermalSoak.truth_for(truth)["f0_at_25c_hz"]
    assert f25.ci95[0] - 0.01 <= f25_true <= f25.ci95[1] + 0.01, (f25.value, f25.ci95, f25_true)
    data = open_run(record.raw_file)
    win = data.table("thermal_soak_windows")
    assert list(win["setpoint_c"]) == [15.0, 25.0, 35.0]
    assert max(abs(win["part_c"] - win["setpoint_c"])) < 0.1  # settled: the case at the set point
    assert sim_station.devices["chamber"].setpoint_c() == 25.0  # back to ambient at the end
    # the raw file gives the same numbers, and the fit figure
    again = {r.name: r.value for r in ThermalSoak(record.params).analysis(data)}
    assert again["f0_tc_ppm_k"] == pytest.approx(tc.value, rel=1e-9)
    figs = ThermalSoak(record.params).figures(data)
    assert [f.key for f in figs] == ["thermal-soak_temperatures", "thermal-soak_fits"]
    assert len(figs[1].figure.axes) == 4
    # the chamber's stream (its link checks): the case lags the air and ends at the last set point
    ch = data.table("chamber")
    assert len(ch["t_s"]) > 100 and abs(ch["part_degc"][-1] - 35.0) < 0.1
    assert min(ch["air_degc"]) == pytest.approx(15.0) and max(ch["air_degc"]) == pytest.approx(35.0)


class _StubCtx:
    """Just enough of a run context for ThermalChamber._settle_at: a clock that sleep advances, a
    frequency that wanders (never settles), an FPGA whose STATUS says whether the PLL is locked."""

    def __init__(self, proc, locked: bool):
        import types

        from drivers.fpga import protocol as fp

        self.t = 0.0
        self.proc = proc
        self.clock = types.SimpleNamespace(now=lambda: self.t)
        status = fp.ST_PLL_LOCKED if locked else 0
        fpga = types.SimpleNamespace(sync=lambda: None, read_register=lambda name: status)
        chamber = types.SimpleNamespace(set_setpoint=lambda c: None)
        self.devices = types.SimpleNamespace(fpga=fpga, chamber=chamber)

    def shared(self, fn, what=""):
        return fn()

    def gather(self, value, what=""):
        return [value]

    def sleep(self, seconds):
        self.t += seconds
        self.n = getattr(self, "n", 0) + 1
        self.proc._f_sum, self.proc._f_n = 100.0 * (-1) ** self.n, 1  # +-100 Hz window to window: drifting


def test_a_unit_whose_pll_lost_the_wave_is_given_up_not_waited_for():
    """A ring whose loops lost the wave (one of sim-mems-thermal-4's draws at seed 0) never settles:
    the settle judgement gives it up after unlocked_windows windows with its PLL unlocked (a batch
    then goes on without it) instead of waiting settle_timeout_s (6 simulated hours)."""
    import threading

    from procedures.thermal_soak import ThermalSoak

    proc = ThermalSoak({"settle_window_s": 10.0, "settle_timeout_s": 3600.0})
    proc._lock = threading.Lock()
    ctx = _StubCtx(proc, locked=False)
    with pytest.raises(RuntimeError, match="unlocked at the end of 4 settle windows"):
        proc._settle_at(ctx, 30.0, 13647.0)
    assert ctx.t == 40.0
    ctx = _StubCtx(proc, locked=True)  # locked but drifting: the timeout, as before
    with pytest.raises(TimeoutError):
        proc._settle_at(ctx, 30.0, 13647.0)
    assert ctx.t > 3600.0


def test_line_run_eol_hrg_thermal_soak_leaves_the_soaks_trim_in_nvm(tmp_path, capsys):
    """The shipped eol-hrg-thermal-soak on sim-hrg-thermal-quick (seed 0): the soak's settled records
    (15, 25, 35 degC) give the thermal trim (bias against the resonator frequency's offset), the
    trim goes into the FPGA and the verification at 20 degC (between two set points, reached from
    35 degC) reads the compensated output; then (PASS) the line's gated trims write it into NVM and
    read it back: the same coefficients the soak reported."""
    from bench.cli import main

    code = main(["line", "run", "eol-hrg-thermal-soak", "--operator", "ada", "--dut", "HRG-000123", "--yes",
                 "--seed", "0", "--lot", "L1", "--runs-dir", str(tmp_path / "runs"), "--json"])
    (rec,) = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert code == 0 and rec["outcome"] == "PASS", rec["summary"]
    m = {x["name"]: x for x in rec["measurements"]}
    tc = m["f0_tc_ppm_k"]
    assert tc["interval"][0] <= tc["truth"] <= tc["interval"][1], tc
    # the trim held the verification's bias to the record's noise (untrimmed it is the bias itself)
    assert m["verify_residual_dph"]["value"] < 4.0 * m["verify_noise_dph"]["value"], m["verify_residual_dph"]
    # and within 1.2 of what the noise and the trim line's interval allow (the target)
    assert m["verify_allowed_dph"]["value"] >= m["verify_noise_dph"]["value"]
    assert m["verify_residual_dph"]["value"] < 1.2 * m["verify_allowed_dph"]["value"]
    back = rec["trims"]["read_back"]
    assert rec["trims"]["written"] and int(back["TRIM_EN"]) == 0x08
    assert back["TRIM_BIAS_DPH"] == pytest.approx(m["thermal_bias_dph"]["value"], rel=1e-6)
    assert back["TRIM_BIAS_DPH_PER_HZ"] == pytest.approx(m["thermal_bias_dph_per_hz"]["value"], rel=1e-6)
    assert back["TRIM_SF_PPM"] == 0.0 and back["TRIM_SF_PPM_PER_HZ"] == 0.0  # the soak measures no scale factor
    chosen = rec["trims"]["chosen"]
    assert chosen["thermal_bias_dph"]["procedure"] == "thermal-soak"
