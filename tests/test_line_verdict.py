"""The line's decision rules (bench/line/verdict.py), on hand-made intervals whose outcome follows
from the definitions: guard band (ILAC G8) on the 95 % interval, value-only with a marginal band."""

import math

import pytest

from bench.line.verdict import (
    ERROR,
    FAIL,
    GUARD_BAND,
    MARGINAL,
    PASS,
    VALUE,
    Limit,
    expanded_uncertainty,
    guard_band,
    judge,
    value_rule,
    worst,
)

NAN, INF = math.nan, math.inf


@pytest.mark.parametrize(("interval", "low", "high", "want"), [
    ((2.0, 3.0), 1.0, 4.0, PASS),          # wholly inside
    ((1.0, 3.0), 1.0, 4.0, PASS),          # touching the low limit: inclusive, inside
    ((2.0, 4.0), 1.0, 4.0, PASS),          # touching the high limit
    ((1.0, 4.0), 1.0, 4.0, PASS),          # exactly the limits
    ((0.5, 2.0), 1.0, 4.0, MARGINAL),      # straddles low
    ((3.0, 4.5), 1.0, 4.0, MARGINAL),      # straddles high
    ((0.0, 5.0), 1.0, 4.0, MARGINAL),      # wider than the limits: straddles both
    ((4.5, 5.0), 1.0, 4.0, FAIL),          # wholly above
    ((0.0, 0.5), 1.0, 4.0, FAIL),          # wholly below
    ((4.0, 5.0), 1.0, 4.0, MARGINAL),      # touches high from outside: the point 4 is inside
    ((0.0, 1.0), 1.0, 4.0, MARGINAL),      # touches low from outside
    ((4.0 + 1e-12, 5.0), 1.0, 4.0, FAIL),  # just outside
    ((5.0, 10.0), None, 4.0, FAIL),        # one-sided (high only)
    ((-1e9, 4.0), None, 4.0, PASS),
    ((3.0, 4.1), None, 4.0, MARGINAL),
    ((1.0, 1e9), 1.0, None, PASS),         # one-sided (low only)
    ((0.9, 2.0), 1.0, None, MARGINAL),
    ((-3.0, 0.99), 1.0, None, FAIL),
    ((NAN, 3.0), 1.0, 4.0, MARGINAL),      # a NaN end is unbounded: never proves PASS
    ((NAN, 0.5), 1.0, 4.0, FAIL),          # ... but the known end can still prove FAIL
    ((2.0, NAN), None, 4.0, MARGINAL),
    ((2.0, NAN), 1.0, None, PASS),         # unbounded above, no high limit: inside
    ((3.0, 2.0), 1.0, 4.0, PASS),          # ends given the wrong way round
])
def test_guard_band(interval, low, high, want):
    assert guard_band(interval, low, high) == want


@pytest.mark.parametrize(("value", "lim", "want"), [
    (2.0, (1.0, 4.0, None, None), PASS),
    (1.0, (1.0, 4.0, None, None), PASS),
    (4.0, (1.0, 4.0, None, None), PASS),
    (4.0001, (1.0, 4.0, None, None), FAIL),
    (0.5, (1.0, 4.0, None, None), FAIL),
    (3.5, (1.0, 4.0, None, 3.0), MARGINAL),  # in the marginal band below high
    (3.0, (1.0, 4.0, None, 3.0), PASS),      # on the band's edge: not beyond it
    (1.5, (1.0, 4.0, 2.0, None), MARGINAL),
    (NAN, (1.0, 4.0, None, None), FAIL),
    (INF, (None, None, None, None), FAIL),
    (-5.0, (None, 4.0, None, None), PASS),
])
def test_value_rule(value, lim, want):
    assert value_rule(value, *lim) == want


def test_expanded_uncertainty_each_side():
    assert expanded_uncertainty(10.0, (9.0, 13.0)) == (1.0, 3.0)  # asymmetric
    assert expanded_uncertainty(10.0, (NAN, 13.0)) == (None, 3.0)
    assert expanded_uncertainty(NAN, (9.0, 13.0)) == (None, None)
    assert expanded_uncertainty(10.0, None) == (None, None)


def test_judge_says_which_rule_decided():
    gb = Limit("x", 1.0, 4.0)
    v = judge(3.5, (3.0, 4.5), gb)
    assert (v.outcome, v.rule, v.u_low, v.u_high) == (MARGINAL, GUARD_BAND, 0.5, 1.0)
    # the same value without an interval: the value rule decides, and says so
    v = judge(3.5, None, gb)
    assert (v.outcome, v.rule) == (PASS, VALUE) and "no 95% interval" in v.note
    # an asymmetric interval whose value is inside but whose upper side reaches out
    v = judge(3.9, (3.8, 4.2), gb)
    assert (v.outcome, round(v.u_low, 9), round(v.u_high, 9)) == (MARGINAL, 0.1, 0.3)
    # the value rule asked for: the interval is not used, the marginal band is
    val = Limit("x", 1.0, 4.0, VALUE, marginal_high=3.0)
    assert judge(3.5, (0.0, 9.0), val).outcome == MARGINAL and judge(3.5, (0.0, 9.0), val).rule == VALUE
    # an interval with no finite end cannot be used: the value decides
    v = judge(2.0, (NAN, NAN), gb)
    assert (v.outcome, v.rule) == (PASS, VALUE)
    # NaN value with a usable interval: the interval decides; NaN without one FAILs
    assert judge(NAN, (2.0, 3.0), gb).outcome == PASS
    assert judge(NAN, None, gb).outcome == FAIL


def test_worst_outcome():
    assert worst([PASS, PASS]) == PASS
    assert worst([PASS, MARGINAL]) == MARGINAL
    assert worst([MARGINAL, FAIL, PASS]) == FAIL
    assert worst([FAIL, ERROR]) == ERROR
    assert worst(["COMPLETE", "SKIPPED", FAIL]) == FAIL  # neither decides
    assert worst(["COMPLETE"]) == ERROR  # nothing checked: not a PASS
    assert worst([]) == ERROR


def test_ilac_g8_conditional_pass_and_fail_are_told_apart_with_the_reason():
    """Issue 32: both were MARGINAL with an empty note; now each says its kind and why."""
    from bench.line.verdict import Limit, judge

    lim = Limit("drift_after_dph", high=0.5, rule="guard-band")
    v = judge(0.45, (0.31, 0.62), lim)
    assert (v.outcome, v.condition) == ("MARGINAL", "conditional pass")
    assert v.note == ("conditional pass: the value 0.45 is inside the limits but its 95 % interval [0.31, 0.62] "
                      "crosses the high limit 0.5 (ILAC G8)")
    v = judge(0.55, (0.41, 0.69), lim)
    assert (v.outcome, v.condition) == ("MARGINAL", "conditional fail")
    assert v.note.startswith("conditional fail: the value 0.55 is outside the limits")
    assert judge(0.3, (0.2, 0.4), lim).condition == "" and judge(0.7, (0.6, 0.8), lim).condition == ""
    band = judge(7.0, None, Limit("drift_after_dph", high=8.0, marginal_high=5.0, rule="value"))
    assert (band.outcome, band.condition) == ("MARGINAL", "marginal band")
    assert "beyond the marginal high 5" in band.note
