"""Issue 31 items 4, 7, 8 and the reports: one axis convention with truth compared across the wrap,
one-sided intervals on a bound, lab limits through the line's judge, truths flagged outside."""

from __future__ import annotations

import math

import pytest

from bench.analysis.axes import axis_deg, axis_with_interval
from bench.numbers import error_in_intervals, truth_outside


def test_an_axis_is_reported_in_0_to_90_with_its_interval_shifted():
    assert axis_deg(-30.0) == pytest.approx(60.0)
    assert axis_deg(-1e-17) == 0.0 and axis_deg(90.0) == 0.0 and axis_deg(44.0) == 44.0
    value, ci = axis_with_interval(-0.5, (-1.5, 0.5))
    assert value == pytest.approx(89.5) and ci == pytest.approx((88.5, 90.5))


def test_truth_across_the_wrap_is_inside_the_interval_of_a_periodic_value():
    """89.5 +- 1 deg and a truth of 0.2 deg: 0.7 deg apart modulo 90, inside; without the period
    the comparison would call it 89 deg off."""
    assert truth_outside(89.5, 0.2, (88.5, 90.5), period=90.0) is False
    assert truth_outside(89.5, 0.2, (88.5, 90.5)) is True
    assert error_in_intervals(89.5, 0.2, (88.5, 90.5), period=90.0) == "−0.70"
    assert truth_outside(10.0, 12.5, (9.0, 11.0), period=90.0) is True


def test_a_one_sided_interval_bounds_one_side_only():
    assert truth_outside(0.0, 0.03, (0.0, math.inf)) is False
    assert truth_outside(0.0, 0.03, (0.0, 0.02)) is True
    assert truth_outside(1.0, 2.0, None) is None


def test_every_procedure_declares_its_axis_angles_periodic_in_90_deg():
    from procedures import find_procedure

    for name, meas in (("hrg-free-decay", ("theta_w_deg", "theta_tau_deg")), ("hrg-damping", ("theta_tau_deg",)),
                       ("hrg-selfcal", ("theta_w_deg", "theta_tau_deg")), ("mems-sweep", ("alpha_deg", "beta_deg"))):
        periods = find_procedure(name).truth_periods()
        for m in meas:
            assert periods.get(m) == 90.0, (name, m)
