"""Several gyros in one chamber on one table (#34): the line's eol-hrg-thermal on sim-hrg-thermal-4
runs the chamber's set points and ramps once for the four units (settling judged from every unit's
own frequency), while each unit's records, fits, verdict and trims are its own; the safe state
takes the chamber to ambient and the table to rest once and cuts every slot's drive."""

from __future__ import annotations

import pytest

from bench.composition import load_station
from drivers.fpga import protocol as fp
from tests.computed_once import computed_once

SERIALS = {1: "HRG-000701", 2: "HRG-000702", 3: "HRG-000703", 4: "HRG-000704"}
#: the shipped limits plus the frequency at 25 degC (judged wide), so each record carries it with its truth
EXTRA_LIMITS = """
[limits.f0_at_25c_hz]
low = 5480.0
high = 5530.0
unit = "Hz"
"""


class _Yes:
    def confirm(self, question: str) -> bool:
        return True

    def show_outcome(self, *args) -> None:
        pass


@pytest.fixture(scope="module")
def thermal_batch(tmp_path_factory):
    """eol-hrg-thermal through the line's batch attempt on sim-hrg-thermal-4 (seed 0), the
    chamber's set-point writes counted at its driver; once a session (tests/computed_once.py)."""
    return computed_once(tmp_path_factory, "thermal-batch",
                         lambda: _thermal_batch(tmp_path_factory.mktemp("thermal-batch")))


def _thermal_batch(tmp) -> dict:
    """The batch's records, each slot's truth, the chamber's set-point writes and the state after."""
    from pathlib import Path

    from bench.line.batch_run import check_batch_sequence, run_batch_attempt
    from bench.line.db import LineDB
    from bench.line.limits import load_limits
    from bench.line.run import LineContext
    from bench.line.sequence import load_sequence
    from bench.results import ResultsStore

    limits_file = tmp / "limits.toml"
    limits_file.write_text(Path("bench/line/limits/hrg-thermal.toml").read_text() + EXTRA_LIMITS)
    url = str(tmp / "results.sqlite")
    store, db = ResultsStore(url, offline_ok=True, spool_dir=tmp / "spool"), LineDB(url)
    seq, limits = load_sequence("bench/line/sequences/eol-hrg-thermal.toml"), load_limits(limits_file)
    ctx = LineContext(seq, limits, "sim-hrg-thermal-4", "tester", tmp, store=store, db=db)
    station = load_station("sim-hrg-thermal-4", seed=0).open()
    try:
        check_batch_sequence(seq, limits, station)
        chamber = station.shared["chamber"]._device
        writes: list[float] = []
        real_set = chamber.set_setpoint

        def counted(c: float) -> None:
            writes.append(c)
            real_set(c)

        chamber.set_setpoint = counted
        records = run_batch_attempt(ctx, station, SERIALS, _Yes())
        truths = {n: station.truth(n) for n in station.slots}
        firmware = {n: station.handles[(n, "fpga")].firmware for n in station.slots}
        after = {
            "drive_on": {n: bool(int(fw.regs["CTRL"]) & fp.DRIVE_EN) for n, fw in firmware.items()},
            "table_rate_dps": station.handles[(None, "table")].mechanics.rate_dps,
            "chamber_setpoint_c": chamber.setpoint_c(),
            "chamber_profile": chamber.status().profile_status,
        }
        return {"records": records, "truths": truths, "writes": writes, "after": after}
    finally:
        station.close()
        store.close()
        db.close()


def _measured(rec) -> dict:
    return {m["name"]: m for m in rec["measurements"]}


def test_every_unit_passes_with_its_own_numbers_against_its_own_truth(thermal_batch):
    recs = {r["slot"]: r for r in thermal_batch["records"]}
    assert sorted(recs) == [1, 2, 3, 4]
    f0 = {}
    for n, rec in recs.items():
        assert rec["serial"] == SERIALS[n] and rec["outcome"] == "PASS", rec["summary"]
        m = _measured(rec)
        truth = thermal_batch["truths"][n]
        # the PLL's frequency: the natural one and the held wave's split (docs/chamber.md)
        f25 = truth["f0_hz"] + truth.get("freq_offset_hz_ref", truth["freq_offset_hz"]) + truth["drive_freq_offset_hz"]
        lo, hi = m["f0_at_25c_hz"]["interval"]
        assert m["f0_at_25c_hz"]["truth"] == pytest.approx(f25, abs=1e-9)
        assert lo <= f25 <= hi, (n, m["f0_at_25c_hz"]["value"], f25)
        assert m["f0_at_25c_hz"]["value"] == pytest.approx(f25, abs=0.2)  # each unit's own f0 (spread ~1.5 Hz)
        f0[n] = f25
        lo, hi = m["f0_tc_ppm_k"]["interval"]
        assert lo <= truth["err_freq_tc_ppm_k"] == 55.0 <= hi
        # the unit's own trim leaves its bias within ~3 of a 60 s record's noise (~1 deg/h)
        assert m["verify_residual_dph"]["value"] < 3.0
    assert max(f0.values()) - min(f0.values()) > 0.5  # the units do differ


def test_each_units_thermal_trim_is_its_own_in_its_own_nvm(thermal_batch):
    trims = {}
    for rec in thermal_batch["records"]:
        t = rec["trims"]
        assert t["written"] and t["nvm"]["valid"] and t["nvm"]["match"], t
        back = t["read_back"]
        assert int(back["TRIM_EN"]) == fp.TRIM_THERMAL
        run_id = t["chosen"]["thermal_bias_dph"]["run_id"]
        assert run_id.endswith(f"-slot{rec['slot']}")  # the unit's own slot's run
        trims[rec["slot"]] = (back["TRIM_BIAS_DPH"], back["TRIM_BIAS_DPH_PER_HZ"])
    biases = [b for b, _ in trims.values()]
    assert len(set(biases)) == 4 and max(biases) - min(biases) > 5.0  # four units, four biases


def test_the_chamber_steps_ran_once_for_the_batch(thermal_batch):
    # set points: t_low (settle), heating, cooling, the verification point, then ambient once at the end
    assert thermal_batch["writes"] == [25.0, 35.0, 25.0, 30.0, 25.0]
    sims = {r["runs"][0]["simulated_s"] for r in thermal_batch["records"]}
    assert len(sims) == 1  # one cycle in virtual time for all four
    (sim_s,) = sims
    # one unit's cycle: 2 x (10 K at 5 degC/min + 60 s tail) of ramp, the settles and records; four in turn
    # would take four times that
    assert 2 * (120.0 + 60.0) < sim_s < 1200.0


def test_the_safe_state_after_the_batch(thermal_batch):
    after = thermal_batch["after"]
    assert after["chamber_setpoint_c"] == 25.0 and after["chamber_profile"] in (0, 1)
    assert after["table_rate_dps"] == 0.0
    assert not any(after["drive_on"].values()), after["drive_on"]
    for rec in thermal_batch["records"]:
        run = rec["runs"][0]
        assert run["safe_state"] is True


def test_a_soak_batch_settles_on_every_units_frequency(tmp_path):
    """thermal-soak on the four units at once: each set point written once, the batch settled when
    every unit's drift is below the limit, each unit's frequency fit against its own truth."""
    from bench.engine.batch import Batch
    from procedures.thermal_soak import ThermalSoak

    params = {"t_low_degc": 25.0, "t_high_degc": 30.0, "points": 3, "settle_window_s": 20.0,
              "settle_ppm_per_min": 1.0, "record_s": 30.0, "max_order": 1}
    station = load_station("sim-hrg-thermal-4", seed=1).open()
    try:
        chamber = station.shared["chamber"]._device
        writes: list[float] = []
        real_set = chamber.set_setpoint
        chamber.set_setpoint = lambda c: (writes.append(c), real_set(c))[1]
        batch = Batch(station, {n: f"S{n}" for n in station.slots}, runs_dir=tmp_path)
        records = batch.run(lambda: ThermalSoak(params))
        truths = {n: station.truth(n) for n in station.slots}
    finally:
        station.close()
    assert writes == [25.0, 27.5, 30.0, 25.0]  # the three set points and ambient at the end, once each
    settle = set()
    for n, rec in records.items():
        assert rec.outcome == "COMPLETE", (n, rec.end_reason)
        got = {m.name: m for m in rec.measurements}
        truth = truths[n]
        f25 = truth["f0_hz"] + truth.get("freq_offset_hz_ref", truth["freq_offset_hz"]) + truth["drive_freq_offset_hz"]
        lo, hi = got["f0_at_25c_hz"].ci95
        assert lo <= f25 <= hi, (n, got["f0_at_25c_hz"].value, f25)
        lo, hi = got["f0_tc_ppm_k"].ci95
        assert lo <= 55.0 <= hi, (n, got["f0_tc_ppm_k"].value)
        settle.add(got["settle_mean_s"].value)
    assert len(settle) == 1  # every unit waited for the slowest: one settle time for all
