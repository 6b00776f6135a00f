"""A capability report that is right (issue 32): grouped by product, sequence and procedure (HRG and
MEMS split_hz never pooled), n in units (a retested unit counts once, by its final attempt), Cp/Cpk
with confidence intervals (chi-square for Cp, Bissell's approximation for Cpk), individuals chart
limits from the moving range, the golden units' drift; hand-made rows with closed-form numbers."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from bench.line.report import render_html, summarize
from bench.line.stats import capability, individuals_chart


class FakeDB:
    """The two queries the report makes, on hand-made rows."""

    def __init__(self, attempts, meas):
        self._a, self._m = attempts, meas

    def attempts(self, lot=None):
        return self._a

    def measurements(self, lot=None):
        return self._m


def _rows():
    attempts, meas = [], []
    t = 0

    def add(serial, attempt, product, sequence, procedure, name, value, low, high, outcome="PASS"):
        nonlocal t
        t += 1
        stamp = f"2026-11-28T00:{t // 60:02d}:{t % 60:02d}"
        attempts.append({"serial": serial, "attempt": attempt, "outcome": outcome, "station": "s1", "lot": "L",
                         "ended_at": stamp, "operator": "ada", "sequence": sequence})
        meas.append({"name": name, "procedure": procedure, "serial": serial, "value": value, "unit": "Hz",
                     "low": low, "high": high, "rule": "guard-band", "outcome": outcome, "ended_at": stamp,
                     "lot": "L", "station": "s1", "attempt": attempt, "product": product, "sequence": sequence})

    for i, v in enumerate([0.0050, 0.0052, 0.0049, 0.0051, 0.0053]):
        add(f"H{i}", 1, "hrg-5500", "eol-hrg", "hrg-free-decay", "split_hz", v, None, 0.008)
    add("H0", 2, "hrg-5500", "eol-hrg", "hrg-free-decay", "split_hz", 0.0048, None, 0.008)  # a retest of H0
    for i, v in enumerate([40.0, 42.0, 41.0, 39.0]):
        add(f"M{i}", 1, "mems-ring", "eol-mems", "mems-sweep", "split_hz", v, None, 60.0)
    return attempts, meas


def test_groups_are_product_sequence_procedure_and_n_is_units():
    s = summarize(FakeDB(*_rows()))
    keys = [(m["product"], m["sequence"], m["procedure"], m["name"], m["n"]) for m in s["measures"]]
    assert keys == [("hrg-5500", "eol-hrg", "hrg-free-decay", "split_hz", 5),
                    ("mems-ring", "eol-mems", "mems-sweep", "split_hz", 4)]
    hrg = s["measures"][0]
    x = np.array([0.0052, 0.0049, 0.0051, 0.0053, 0.0048])  # H0's final attempt, in the time order tested
    assert [r["value"] for r in hrg["final"]] == list(x)
    assert hrg["cpk"] == pytest.approx((0.008 - x.mean()) / (3 * x.std(ddof=1)), rel=1e-12)
    html = render_html(s)
    assert "Bissell" in html and "mean ± 2.66·MR-bar" in html and "mems-ring" in html


def test_capability_intervals_against_their_formulas():
    x = np.array([9.0, 10.0, 11.0, 10.5, 9.5, 10.2, 9.8, 10.1])
    n, sd, mu = x.size, x.std(ddof=1), x.mean()
    c = capability(x, 4.0, 22.0)
    cp, cpk = 18 / (6 * sd), (mu - 4.0) / (3 * sd)
    assert c["cp_ci"] == pytest.approx((cp * math.sqrt(stats.chi2.ppf(0.025, n - 1) / (n - 1)),
                                        cp * math.sqrt(stats.chi2.ppf(0.975, n - 1) / (n - 1))), rel=1e-12)
    half = 1.959963984540054 * math.sqrt(1 / (9 * n) + cpk**2 / (2 * (n - 1)))
    assert c["cpk_ci"] == pytest.approx((cpk - half, cpk + half), rel=1e-9)
    assert capability([1.0], 0.0, 2.0)["cpk_ci"] is None


def test_individuals_chart_limits_come_from_the_moving_range():
    x = [10.0, 12.0, 11.0, 13.0, 30.0]  # MR 2, 1, 2, 17: MR-bar 5.5
    ch = individuals_chart(x)
    assert ch["mr_bar"] == pytest.approx(5.5) and ch["sigma_within"] == pytest.approx(5.5 / 1.128)
    assert ch["ucl"] == pytest.approx(15.2 + 3 * 5.5 / 1.128) and ch["lcl"] == pytest.approx(15.2 - 3 * 5.5 / 1.128)
    assert ch["outside"] == [4]
    # a slow trend: the overall sigma is inflated, the moving range is not
    trend = np.linspace(0.0, 10.0, 50)
    assert individuals_chart(trend)["sigma_within"] < 0.2 * trend.std(ddof=1)


def test_the_golden_drift_is_charted(tmp_path):
    from bench.line.station_state import append_log

    append_log(tmp_path, "st-1", {"event": "golden", "serial": "G1", "held": False, "drifts": [
        {"name": "tau_s", "unit": "s", "reference": 300.0, "limit": 2.0, "value": 303.0, "drift": 3.0, "ok": False}]})
    s = summarize(FakeDB(*_rows()), runs_dir=tmp_path)
    assert [(g["station"], g["name"], g["drift"], g["ok"]) for g in s["golden"]] == [("st-1", "tau_s", 3.0, False)]
    html = render_html(s)
    assert "Golden units: drift from their references" in html and "PAST LIMIT: station locked" in html
