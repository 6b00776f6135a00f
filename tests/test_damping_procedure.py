"""The `hrg-damping` procedure end to end on the simulated `sim-hrg` station (real drivers over
loopback, lockstep clock), checked against the simulator's truth.

Kept short for CI: a 60 s decay at 20 deg/s streamed at 200 Hz (the design's regime: the energy
bound there is far tighter than at the patent's 500 deg/s) and 45 s drift records at a 4 deg/s precession (two turns
of the 4-theta harmonic each).  Tolerances come from the fit's own 95 % intervals (validated by
Monte Carlo in test_damping.py): the truth must lie within 2x the half-width (about 4 sigma)."""

from __future__ import annotations

import math

import pytest

from procedures import find_procedure
from procedures.hrg_damping import HrgDamping

PARAMS = {
    "rate_dps": 20.0,
    "record_s": 60.0,
    "stream_hz": 200.0,  # the FPGA streams every 5th sample during the decay
    "verify_rate_dps": 4.0,
    "verify_s": 45.0,
    "verify_settle_s": 5.0,  # the loops settle after whole-angle starts (docs/damping_drift.md)
}


def _within(res, truth: float, factor: float = 2.0) -> bool:
    lo, hi = res.ci95
    half = 0.5 * (hi - lo)
    return abs(res.value - truth) <= factor * half


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """One run shared by the checks below (the procedure is the expensive part)."""
    from bench.composition.sim_station import SimStation
    from bench.engine import Runner
    from bench.results import ResultsStore

    tmp = tmp_path_factory.mktemp("hrg_damping")
    station = SimStation("sim-hrg", seed=0).open()
    store = ResultsStore(tmp / "results.sqlite")
    events: list = []
    try:
        runner = Runner(station, runs_dir=tmp / "runs", store=store)
        runner.bus.subscribe(events.append)
        record = runner.run(HrgDamping, PARAMS)
        yield record, events, station.truth()
    finally:
        store.close()
        station.close()


def test_registered_under_its_name():
    assert find_procedure("hrg-damping") is HrgDamping
    assert [s for s, _ in HrgDamping.step_specs()] == [
        "excite", "spin", "wait_stable", "cut_drive", "record", "elements", "fit", "stop_table", "compensate_step"
    ]


def test_runs_to_completion_with_safe_state(run):
    record, events, _ = run
    assert record.outcome == "COMPLETE", record.end_reason
    assert record.safe_state
    started = [e.name for e in events if type(e).__name__ == "StepStarted"]
    assert started == [s for s, _ in HrgDamping.step_specs()]


def test_decay_streamed_at_the_requested_rate(run):
    """stream_hz = 200: the decay window of the raw file holds 200 samples a second."""
    from bench.recorder import RunData

    record, _, _ = run
    with RunData(record.raw_file) as data:
        kind, t0, t1 = data.array("damping_windows")[0]
        t = data.table("fpga")["t_s"]
        n = int(((t > t0) & (t <= t1)).sum())
    assert kind == 0.0 and n == pytest.approx(200 * (t1 - t0), abs=2)


def test_measurements_match_the_simulator_truth(run):
    """theta_tau, Delta(1/tau), tau and Q within about 4 sigma of the truth (intervals from the fit)."""
    record, _, truth = run
    m = {r.name: r for r in record.measurements}
    for name in ("theta_tau_deg", "delta_inv_tau_per_s", "tau_s", "q_factor"):
        assert m[name].ci95 is not None
        assert _within(m[name], truth[name]), (name, m[name].value, m[name].ci95, truth[name])
    assert 0.0 <= m["theta_tau_deg"].value < 90.0


def test_compensation_reduces_the_angle_drift(run):
    """Before: (D/4)/K = 29.8 deg/h output-referred (within its interval, 2x); after writing the
    identified coefficients to the FPGA the 4-theta harmonic falls at least 5x (the rest is noise
    and the split's own drift)."""
    record, _, truth = run
    m = {r.name: r for r in record.measurements}
    expected_dph = math.degrees(truth["delta_inv_tau_per_s"] / 4 / truth["bryan_factor"]) * 3600
    assert _within(m["drift_before_dph"], expected_dph)
    assert m["drift_after_dph"].value < m["drift_before_dph"].value / 5
    assert m["drift_reduction_ratio"].value > 5


def test_fit_curves_are_published(run):
    _, events, _ = run
    fits = {e.name: e.curves for e in events if type(e).__name__ == "FitUpdate"}
    assert {"hrg-damping energy", "hrg-damping residuals", "hrg-damping theta", "hrg-damping quadrature",
            "hrg-damping drift before", "hrg-damping drift after"} <= set(fits)
    assert len(fits["hrg-damping energy"]["energy_fit"]) <= 2000


def test_analysis_refits_the_recorded_run(run):
    """`gyrobench analyze` path: the recorded file gives the same damping estimates."""
    from bench.recorder import RunData

    record, _, _ = run
    with RunData(record.raw_file) as data:
        again = {r.name: r.value for r in HrgDamping(record.params).analysis(data)}
    live = {r.name: r.value for r in record.measurements}
    for name in ("theta_tau_deg", "delta_inv_tau_per_s", "tau_s", "drift_before_dph", "drift_after_dph",
                 "drift_after_mean_dph", "drift_after_8theta_dph", "drift_after_rest_rms_dph",
                 "drift_after_4theta_expected_dph", "drift_before_4theta_phase_deg", "drift_after_8theta_phase_deg"):
        assert again[name] == pytest.approx(live[name], rel=1e-6), name


def test_bad_parameters_are_refused_before_anything_moves():
    from bench.engine import ParamError

    with pytest.raises(ParamError, match="rate_dps=2000"):
        HrgDamping({"rate_dps": 2000.0})
    with pytest.raises(ParamError, match="fit_method='newton'"):
        HrgDamping({"fit_method": "newton"})


def test_drift_reported_in_full_and_the_loops_add_none(run):
    """The drift against the wave angle in full (issue 19): after compensation the mean and the 8 and
    12 theta terms are consistent with zero and the 4 theta term is no larger than the decay fit's
    own error predicts (its interval reaches below that 95 % bound); before, the 4 theta term is
    the damping drift (D/4)/K and nothing else is there either.  "Consistent with zero" as for the
    other checks here: within 2x the interval's half-width (an amplitude: within 2x its reach).
    (The loops used to add a -40 deg/h mean and a 25 deg/h 8 theta term of their own here.)"""
    record, _, truth = run
    m = {r.name: r for r in record.measurements}
    expected_dph = math.degrees(truth["delta_inv_tau_per_s"] / 4 / truth["bryan_factor"]) * 3600
    for name in ("before", "after"):
        # the mean: read from the angle record to +-0.03 deg/h, the loops' own -0.2 deg/h shows
        # (the block slopes' +-1.5 hid it; docs/damping_drift.md): within 0.3 deg/h of zero
        mean = m[f"drift_{name}_mean_dph"]
        assert abs(mean.value) <= max(2.0 * 0.5 * (mean.ci95[1] - mean.ci95[0]), 0.3), mean
        for order in (8, 12):
            res = m[f"drift_{name}_{order}theta_dph"]
            assert res.value <= 2.0 * (res.ci95[1] - res.value), (name, order, res)
        assert m[f"drift_{name}_rest_rms_dph"].value > 0
    assert _within(m["drift_before_4theta_dph"], expected_dph)
    assert m["drift_after_4theta_dph"].ci95[0] <= m["drift_after_4theta_expected_dph"].ci95[1]
    assert m["drift_after_4theta_dph"].value == pytest.approx(m["drift_after_dph"].value, abs=0.5)


def test_reports_exactly_its_declared_measurements(run):
    """With `compensate` on: every declared measurement (the drift ones included), nothing else,
    nothing NOT_MEASURED; with it off the drift ones are not expected."""
    record, _, _ = run
    assert PARAMS.get("compensate", True)
    declared = {m.name for m in HrgDamping.measurements}
    assert {r.name for r in record.measurements} == declared
    assert all(r.measured for r in record.measurements)
    off = HrgDamping({**PARAMS, "compensate": False})
    expected_off = {m.name for m in HrgDamping.measurements if m.applies(off)}
    assert not any(n.startswith("drift_") and n != "drift_predicted_dph" for n in expected_off)
