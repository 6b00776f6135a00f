"""The mems-sweep procedure end to end: engine, real SCPI front-end driver over loopback, the
simulated MEMS ring (Maslov's identified model), identification against the simulator's truth."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bench.analysis.maslov import choose_model
from bench.composition.sim_station import SimStation
from bench.engine import Runner
from bench.engine.params import ParamError
from bench.recorder import open_run
from procedures.hrg_free_decay import HrgFreeDecay
from procedures.mems_sweep import MemsSweep


@pytest.fixture(scope="module")
def sweep_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("mems")
    station = SimStation("sim-mems", seed=0).open()  # the built-in station: front end, table and FPGA
    try:
        record = Runner(station, runs_dir=tmp / "runs").run(MemsSweep, {"n_points": 17})
        yield record, station.truth()
    finally:
        station.close()


def test_mems_sweep_identifies_the_simulated_ring(sweep_run):
    """Truth: the sim's preset (the paper's cubic model).  Tolerances: each value inside its own
    95 % interval widened 1.5x (the steady-state wait of 8 time constants leaves a residual
    transient of e^-8 ~ 3e-4 of a step, below the noise) and the cubic model chosen."""
    record, truth = sweep_run
    assert record.outcome == "COMPLETE", record.traceback
    m = {r.name: r for r in record.measurements}
    assert m["chosen_model_order"].value == 3.0
    assert m["sigma_linear"].value > 10 * m["sigma_cubic"].value
    expected = {
        "Q": truth["q_factor"],
        "split_hz": truth["split_hz"],
        "damping_anisotropy_per_s": truth["damping_anisotropy_per_s"],
        "freq_offset_hz": truth["freq_offset_hz"],
        "alpha_deg": truth["alpha_deg"],
        "beta_deg": truth["beta_deg"],
        "xi": 18.217,
        "gamma": 43.029,
        "u1": 50.0 * 0.888 * math.sin(math.radians(46.43)),  # drive_gain x amplitude x sin(phase)
    }
    for name, value in expected.items():
        lo, hi = m[name].ci95
        mid, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
        assert abs(value - mid) <= 1.5 * half, (name, m[name].value, value, (lo, hi))
    assert m["hysteresis_max_amplitude"].value < 0.01  # the paper's drive: no bistability


def test_recorded_sweep_refits_to_the_same_answer(sweep_run):
    """The analysis hook on the raw file gives the run's own measurements (same code, same data)."""
    record, _ = sweep_run
    data = open_run(record.raw_file)
    tab = data.table("sweep")
    assert len(tab["freq_hz"]) == 2 * 17 and set(np.unique(tab["direction"])) == {-1.0, 1.0}
    assert np.all(tab["settled"] == 1.0)
    refit = {r.name: r.value for r in MemsSweep(record.params).analysis(data)}
    for r in record.measurements:
        assert refit[r.name] == pytest.approx(r.value, rel=1e-9, abs=1e-12), r.name
    fits = data.fits()
    assert {"sweep_model", "polar_ch1_measured", "polar_ch1_model_cubic"} <= set(fits)


def test_bad_sweep_range_is_rejected_before_anything_moves():
    with pytest.raises(ParamError, match=r"^stop_hz=13640 Hz is not above the limit 13650 Hz \(start_hz\)$"):
        MemsSweep({"start_hz": 13650.0, "stop_hz": 13640.0})
    with pytest.raises(ParamError, match="n_points"):
        MemsSweep({"n_points": 2})


def test_model_choice_prefers_the_simplest_model_not_beaten_by_5_percent():
    assert choose_model({"linear": 0.295, "cubic": 0.0926, "quintic": 0.0656}, 0.05) == "quintic"  # the paper
    assert choose_model({"linear": 0.75, "cubic": 0.015, "quintic": 0.0149}, 0.05) == "cubic"
    assert choose_model({"linear": 0.1, "cubic": 0.099, "quintic": 0.01}, 0.05) == "linear"


@pytest.fixture(scope="module")
def decay_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("hrg")
    station = SimStation("sim-hrg", seed=0).open()
    try:
        record = Runner(station, runs_dir=tmp / "runs").run(HrgFreeDecay, {"record_s": 60.0, "rate_dps": 20.0})
        yield record, station.truth()
    finally:
        station.close()


def test_hrg_free_decay_identifies_the_simulated_shell(decay_run):
    """Truth: the sim-hrg preset (tau 300 s, D 1.6e-4 1/s at 20 deg, split 5 mHz at 10 deg,
    K 0.277), driven by the FPGA's loops, spun by the rate table, recorded from the FPGA stream
    at 100 Hz for 60 s.  Each value inside its own 95 % interval widened 1.5x, for the default
    output-error fit and for the paper's equation-error fit reported beside it (names ending _ee);
    the output-error intervals of tau and Q at least 10x narrower."""
    record, truth = decay_run
    assert record.outcome == "COMPLETE", record.traceback
    m = {r.name: r for r in record.measurements}
    for name in ("tau_s", "q_factor", "split_hz", "theta_w_deg", "delta_inv_tau_per_s", "damping_anisotropy_per_s",
                 "theta_tau_deg", "bryan_factor", "freq_offset_hz"):
        for suffix in ("", "_ee"):
            lo, hi = m[name + suffix].ci95
            mid, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
            assert abs(truth[name] - mid) <= 1.5 * half + 1e-12, (name + suffix, m[name].value, truth[name], (lo, hi))
    for name in ("tau_s", "q_factor"):
        width = m[name].ci95[1] - m[name].ci95[0]
        assert 10 * width < m[name + "_ee"].ci95[1] - m[name + "_ee"].ci95[0], name
    assert m["bryan_factor"].value == pytest.approx(0.277, rel=1e-4)  # nu is the best-determined parameter


def test_recorded_decay_refits_to_the_same_answer(decay_run):
    record, _ = decay_run
    data = open_run(record.raw_file)
    refit = {r.name: r.value for r in HrgFreeDecay(record.params).analysis(data)}
    for r in record.measurements:
        assert refit[r.name] == pytest.approx(r.value, rel=1e-9, abs=1e-15), r.name


def _declared_set(cls, record, **state) -> set[str]:
    """The declared measurements whose condition holds for the run's parameters (and state)."""
    proc = cls(record.params)
    vars(proc).update(state)
    return {m.name for m in cls.measurements if m.applies(proc)}


def test_each_run_reports_exactly_its_declared_measurements(sweep_run, decay_run):
    """mems-sweep (cubic chosen: xi, no kappa) and hrg-free-decay (linear, output-error: the `_ee`
    twins, no xi or kappa) report their declared set, nothing NOT_MEASURED, nothing else."""
    for cls, (record, _), state in ((MemsSweep, sweep_run, {"chosen_model": "cubic"}), (HrgFreeDecay, decay_run, {})):
        assert "NOT_MEASURED" not in {r.outcome for r in record.measurements}, cls.name
        got = {r.name for r in record.measurements}
        assert got == _declared_set(cls, record, **state), (cls.name, got ^ _declared_set(cls, record, **state))
    assert {"xi", "kappa"} & {r.name for r in sweep_run[0].measurements} == {"xi"}
    decay_names = {r.name for r in decay_run[0].measurements}
    assert "tau_s_ee" in decay_names and "maslov_xi" not in decay_names and "maslov_xi_ee" not in decay_names
