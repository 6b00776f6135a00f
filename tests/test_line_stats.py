"""Yield and process capability on hand-made rows whose numbers follow from the definitions."""

import math

import pytest

from bench.line.stats import capability, final_attempts, yield_by


def _a(serial, attempt, outcome, station="s1"):
    return {"serial": serial, "attempt": attempt, "outcome": outcome, "station": station, "lot": "L",
            "ended_at": "2026-11-23T10:00:00"}


def test_yield_counts_the_final_attempt_and_the_first_apart():
    rows = [_a("A", 1, "MARGINAL"), _a("A", 2, "PASS"), _a("B", 1, "PASS"), _a("C", 1, "FAIL"),
            _a("D", 1, "MARGINAL"), _a("D", 2, "MARGINAL")]
    (r,) = yield_by(rows, lambda a: a["lot"])
    assert (r["units"], r["attempts"]) == (4, 6)
    assert r["first_pass_yield"] == 0.25 and r["final_yield"] == 0.5  # B first time; A after its retest
    assert (r["PASS"], r["MARGINAL"], r["FAIL"], r["ERROR"]) == (2, 1, 1, 0)
    assert final_attempts(rows)["A"]["attempt"] == 2


def test_capability_against_closed_form():
    x = [9.0, 10.0, 11.0]  # mean 10, s = 1
    c = capability(x, 4.0, 22.0)
    assert c["cp"] == pytest.approx(18 / 6) and c["cpk"] == pytest.approx(6 / 3)  # nearer side: 10 - 4
    one = capability(x, None, 13.0)
    assert one["cp"] is None and one["cpk"] == pytest.approx(1.0)
    assert capability([1.0], 0.0, 2.0)["cpk"] is None  # one value: no sigma
    assert capability([1.0, 1.0], 0.0, 2.0)["cpk"] is None  # no spread
    assert capability([math.nan, None, 9.0, 11.0], 0.0, 20.0)["n"] == 2  # unmeasured values left out
