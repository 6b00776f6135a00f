"""Every procedure runs on the realistic stations (sim-hrg-realistic, sim-mems-realistic) briefly:
it completes (its results may be biased by the unit's error sources: docs/sensitivity.md), takes
K and f0 from the station's nominal values, and the nominal values' error shows where the closed
form says it must."""

from __future__ import annotations

import math

import pytest

from bench.composition.sim_station import SimStation
from bench.engine import Runner
from procedures import all_procedures, find_procedure

HRG_RUNS = {
    "table-spin": {"hold_s": 1.0},
    "hrg-damping": {"rate_dps": 20.0, "record_s": 60.0, "stream_hz": 200.0, "verify_rate_dps": 4.0,
                    "verify_s": 45.0, "verify_settle_s": 2.0},
    "hrg-free-decay": {"record_s": 60.0},
    "hrg-selfcal": {"cycles": 3, "precession_dps": 0.25, "settle_s": 10.0},
    "cvg-allan": {"record_s": 600.0, "settle_s": 10.0},
    "cvg-bias": {"record_s": 20.0, "turn_ons": 2, "quench_s": 6.0, "settle_s": 10.0},
    "cvg-scale-factor": {"max_rate_dps": 36.0, "steps": 2, "average_s": 20.0, "settle_s": 3.0},
}
MEMS_RUNS = {"mems-sweep": {"n_points": 17}}
#: procedures that need a device the realistic stations lack (a chamber): run on the realistic HRG
#: in its chamber (sim-hrg-thermal, -quick) by their own tests (tests/test_thermal_soak.py, test_thermal_ramp.py)
ELSEWHERE = {"thermal-soak", "thermal-ramp"}
#: outcomes of a run that ended as planned (a verdict, or results without limits)
ENDED = {"COMPLETE", "PASS", "FAIL", "MARGINAL"}


def _run_all(station_name: str, runs: dict, tmp) -> tuple[dict, dict, dict]:
    station = SimStation(station_name, seed=1).open()
    try:
        records = {name: Runner(station, runs_dir=tmp / "runs").run(find_procedure(name), params)
                   for name, params in runs.items()}
        return records, station.truth(), station.nominal
    finally:
        station.close()


@pytest.fixture(scope="module")
def hrg(tmp_path_factory):
    return _run_all("sim-hrg-realistic", HRG_RUNS, tmp_path_factory.mktemp("hrg_realistic"))


@pytest.fixture(scope="module")
def mems(tmp_path_factory):
    return _run_all("sim-mems-realistic", MEMS_RUNS, tmp_path_factory.mktemp("mems_realistic"))


def test_every_procedure_is_run_here():
    assert set(all_procedures()) == set(HRG_RUNS) | set(MEMS_RUNS) | ELSEWHERE


@pytest.mark.parametrize("name", sorted(HRG_RUNS))
def test_hrg_procedures_complete_on_the_realistic_hrg(hrg, name):
    records, _, nominal = hrg
    rec = records[name]
    assert rec.outcome in ENDED, (rec.end_reason, rec.traceback)
    assert rec.measurements and all(math.isfinite(m.value) for m in rec.measurements)
    for param, key in find_procedure(name).nominal_params.items():  # the station's, recorded with the run
        assert rec.params[param] == nominal[key]


def test_nominal_f0_error_shows_in_the_free_decay(hrg):
    """The free decay refers c_m to the nominal f0 it is given (5500 Hz): the unit's 3.2 Hz above
    it reads as a frequency offset of f0_true - f0_nominal, and Q = w_nominal / gamma comes out
    f0_nominal / f0_true low (beside the pickoffs' bias on gamma); K = nu / (4 Omega) needs no
    nominal value and finds the unit's own."""
    records, truth, nominal = hrg
    m = {r.name: r for r in records["hrg-free-decay"].measurements}
    assert m["freq_offset_hz"].value == pytest.approx(truth["f0_hz"] - nominal["f0_hz"], abs=1e-6)
    assert m["bryan_factor"].value == pytest.approx(truth["bryan_factor"], rel=1e-4)
    assert m["bryan_factor"].value != pytest.approx(nominal["bryan_factor"], rel=1e-3)


def test_scale_factor_series_finds_the_units_k(hrg):
    """Whole-angle's scale factor is -K of the unit (0.2745), not the nominal -0.277 a rate worked
    out with the nominal K would assume (0.9 % off)."""
    records, truth, nominal = hrg
    sf = {r.name: r for r in records["cvg-scale-factor"].measurements}["scale_factor"]
    lo, hi = sf.ci95
    assert lo <= -truth["bryan_factor"] <= hi
    assert not lo <= -nominal["bryan_factor"] <= hi


def test_mems_sweep_on_the_realistic_ring(mems):
    """The sweep completes; its frequency offset is referred to the nominal f0, so it reads the
    unit's own offset plus f0_true - f0_nominal (3 Hz)."""
    records, truth, nominal = mems
    rec = records["mems-sweep"]
    assert rec.outcome in ENDED, (rec.end_reason, rec.traceback)
    assert rec.params["natural_freq_hz"] == nominal["f0_hz"] and rec.params["bryan_factor"] == nominal["bryan_factor"]
    m = {r.name: r for r in rec.measurements}
    expected = truth["freq_offset_hz"] + truth["f0_hz"] - nominal["f0_hz"]
    assert m["freq_offset_hz"].value == pytest.approx(expected, abs=0.05)
