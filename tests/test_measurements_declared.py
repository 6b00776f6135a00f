"""Measurements declared up front (issue 14, section 2): a name not declared or a unit not the
declared one ends the run ERROR; a declared measurement never reported is recorded NOT_MEASURED
only when its condition holds; the marginal band reaches --json, the raw file and the store; the
simulator's truth is found through the declaration."""

from __future__ import annotations

import json
import math

import pytest

from bench.clock import SimClock
from bench.engine import (
    NOT_MEASURED,
    GuardedClock,
    Limits,
    Measurement,
    MeasurementError,
    Param,
    Procedure,
    Result,
    Runner,
    SafeStateReport,
    step,
)
from bench.recorder import open_run
from bench.results import ResultsStore
from simulators.physics.params import preset
from simulators.world import World


class _Station:
    """The station protocol the runner needs, over a lockstep simulated world, no devices."""

    id = "fake"
    simulated = True
    seed = 0

    def __init__(self) -> None:
        self.world = World(preset("hrg"), seed=0)
        self.clock = GuardedClock(SimClock(self.world))
        self.devices: dict = {}

    def safe_state(self) -> SafeStateReport:
        return SafeStateReport(confirmed=True)

    def truth(self) -> dict[str, float]:
        return {"tau_s": 300.0, "split_hz": 0.005}

    def describe(self) -> dict:
        return {"id": self.id}

    def check_links(self) -> None:
        pass


class Reports(Procedure):
    """Reports what its parameters say, against its declarations."""

    name = "reports"
    report_name = Param("a_deg", doc="name reported")
    report_unit = Param("", doc="unit reported ('' = leave it to the declaration)")
    extra = Param(False, doc="the run also measures b_s")

    measurements = (
        Measurement("a_deg", "deg", "an angle", truth="tau_s", limits=Limits(-6, 6, -5.5, 5.5)),
        Measurement("b_s", "s", "a time, measured only with `extra`", truth=lambda t: t["tau_s"] / 2,
                    when=lambda p: p.extra, when_doc="extra"),
        Measurement("c_hz", "Hz", "a frequency with limits, measured only with `extra`", limits=(0.0, 1.0),
                    when=lambda p: p.extra, when_doc="extra"),
    )

    @step
    def measure(self, ctx):
        ctx.sleep(0.1)
        ctx.measure(self.report_name, 5.7, self.report_unit or None)


def _run(tmp_path=None, **params):
    runner = Runner(_Station(), runs_dir=None if tmp_path is None else tmp_path / "runs")
    return runner.run(Reports, params)


def test_an_undeclared_name_ends_the_run_error_naming_it():
    rec = _run(report_name="z_deg")
    assert rec.outcome == "ERROR"
    assert "measurement 'z_deg' is not declared by procedure 'reports'" in rec.end_reason
    assert "a_deg, b_s, c_hz" in rec.end_reason and rec.safe_state


def test_a_unit_other_than_the_declared_one_ends_the_run_error():
    rec = _run(report_unit="rad")
    assert rec.outcome == "ERROR"
    assert "measurement 'a_deg' of procedure 'reports' reported in 'rad'; it is declared in 'deg'" in rec.end_reason


def test_the_result_takes_unit_doc_and_limits_from_its_declaration():
    rec = _run()
    (a,) = rec.measurements  # `extra` off: b_s and c_hz are not expected, so not NOT_MEASURED either
    assert (a.name, a.unit, a.doc, a.limits) == ("a_deg", "deg", "an angle", Limits(-6, 6, -5.5, 5.5))
    assert a.outcome == "MARGINAL" and rec.outcome == "MARGINAL"
    proc = Reports()
    with pytest.raises(MeasurementError, match="'nope' is not declared"):
        proc.resolve_result(Result("nope", 1.0))
    given = proc.resolve_result(Result("a_deg", 1.0, "deg", limits=(0, 2)))
    assert given.limits == Limits(0, 2)  # limits given where reported win over the defaults


def test_not_measured_appears_only_under_its_condition(tmp_path):
    rec = _run(tmp_path, extra=True)
    out = {r.name: r.outcome for r in rec.measurements}
    assert out == {"a_deg": "MARGINAL", "b_s": NOT_MEASURED, "c_hz": NOT_MEASURED}
    assert rec.outcome == "FAIL"  # c_hz has limits and was not measured: the run cannot pass
    js = json.loads(json.dumps(rec.as_json()))
    assert js["measurements"]["b_s"] == {"value": None, "unit": "s", "ci95": None, "limits": None, "marginal": None,
                                         "outcome": NOT_MEASURED}
    with open_run(rec.raw_file) as data:
        rows = {m["name"]: m for m in data.measurements()}
        assert rows["b_s"]["outcome"] == NOT_MEASURED and rows["c_hz"]["low"] == 0.0
        assert data.attrs["result"]["measurements"]["c_hz"]["outcome"] == NOT_MEASURED
    # without the condition the declared measurements are simply not expected
    assert [r.name for r in _run(extra=False).measurements] == ["a_deg"]


def test_the_marginal_band_reaches_json_the_raw_file_and_the_store(tmp_path):
    rec = _run(tmp_path)
    js = json.loads(json.dumps(rec.as_json()))  # what `gyrobench run --json` prints
    assert js["measurements"]["a_deg"]["limits"] == [-6, 6]
    assert js["measurements"]["a_deg"]["marginal"] == [-5.5, 5.5]
    with open_run(rec.raw_file) as data:
        (row,) = data.measurements()
        assert (row["low"], row["high"], row["marginal_low"], row["marginal_high"]) == (-6, 6, -5.5, 5.5)
        assert data.attrs["result"]["measurements"]["a_deg"]["marginal"] == [-5.5, 5.5]
    store = ResultsStore(tmp_path / "results.sqlite")
    try:
        store.save_run(_run(extra=True))
        run = store.get_run("last")
        rows = {m["name"]: m for m in run["measurements"]}
        assert rows["a_deg"]["marginal_high"] == 5.5 and rows["b_s"]["outcome"] == NOT_MEASURED
        assert rows["b_s"]["value"] is None
    finally:
        store.close()


def test_truth_is_found_through_the_declaration():
    """a_deg's truth is the station's tau_s and b_s's is computed: no name matches a truth key."""
    truth = Reports.truth_for(_Station().truth())
    assert truth == {"a_deg": 300.0, "b_s": 150.0}  # c_hz: no truth rule
    assert Reports.truth_for(None) == {} and Reports.truth_for({"other": 1.0}) == {}
    assert math.isnan(Reports.measurements[1].not_measured(Reports()).value)
