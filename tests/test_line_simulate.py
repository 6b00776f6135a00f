"""A simulated lot of 5 units through the short MEMS sequence: every outcome right for the unit's
drawn truth, and the line report's yield and Cpk equal to what the JSON records give."""

import contextlib
import io
import json
from pathlib import Path

import numpy as np
import pytest

from bench.cli import main
from bench.line.db import LineDB
from bench.line.record import SCHEMA_PATH
from bench.line.report import render_html, summarize
from bench.line.simulate import check_lot, expected_outcome
from simulators.lot import draw_units

SEED, UNITS = 1, 5


@pytest.fixture(scope="module")
def lot(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("lot")
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = main(["line", "simulate", "--units", str(UNITS), "--seed", str(SEED), "--sequence", "ci-mems",
                     "--runs-dir", str(tmp), "--json"])
    js = json.loads(out.getvalue().strip().splitlines()[-1])
    records = [json.loads(Path(p).read_text()) for p in js["records"]]
    return code, js, records, tmp


def test_draws_are_reproducible_and_some_out_of_spec():
    a, b = draw_units("mems", 8, 3, "L"), draw_units("mems", 8, 3, "L")
    assert [u.params for u in a] == [u.params for u in b]
    assert [u.pushed for u in a] == [None, "tau_s", None, None, None, "split_hz", None, None]


def test_every_outcome_right_for_its_truth(lot):
    code, js, records, _ = lot
    assert code == 0 and js["wrong"] == [] and check_lot(records) == []
    assert js["units"] == UNITS and len(records) == UNITS  # ci-mems does not retest
    outcomes = {r["serial"]: r["outcome"] for r in records}
    # unit 2 has its tau pushed to 0.0395 s: Q = pi f0 tau = 1693, below the low limit 1800 by far
    # more than its interval (a few units of Q wide); the others were drawn inside by far more
    assert outcomes["sim-1-002"] == "FAIL"
    assert sum(o == "PASS" for o in outcomes.values()) >= 3
    for r in records:
        want, _ = expected_outcome(r)
        assert want in (None, r["outcome"])
        q = next(m for m in r["measurements"] if m["name"] == "Q")
        assert q["truth"] is not None and q["rule"] == "guard-band"
        assert q["interval"][0] <= q["value"] <= q["interval"][1]


def test_records_match_the_schema(lot):
    jsonschema = pytest.importorskip("jsonschema")
    schema = json.loads(SCHEMA_PATH.read_text())
    for r in lot[2]:
        jsonschema.validate(r, schema)


def test_report_agrees_with_the_records(lot):
    _, js, records, tmp = lot
    db = LineDB(tmp / "results.sqlite")
    try:
        s = summarize(db, lot=js["lot"])
        html = render_html(s)
    finally:
        db.close()
    (by_lot,) = s["by_lot"]
    passed = sum(r["outcome"] == "PASS" for r in records)
    assert by_lot["units"] == UNITS and by_lot["final_yield"] == passed / UNITS
    assert by_lot["FAIL"] == sum(r["outcome"] == "FAIL" for r in records)
    # Cpk of Q from the records themselves: min(high - mean, mean - low) / 3 s
    q = np.array([m["value"] for r in records for m in r["measurements"] if m["name"] == "Q"])
    cpk = min(2200.0 - q.mean(), q.mean() - 1800.0) / (3 * q.std(ddof=1))
    cp = 400.0 / (6 * q.std(ddof=1))
    mq = next(m for m in s["measures"] if m["name"] == "Q")
    assert mq["cpk"] == pytest.approx(cpk, rel=1e-12) and mq["cp"] == pytest.approx(cp, rel=1e-12)
    split = next(m for m in s["measures"] if m["name"] == "split_hz")
    assert split["cp"] is None and split["cpk"] is not None  # one-sided limit: no Cp
    assert f"{100 * passed / UNITS:.1f} %" in html and "<svg" in html and "sim-1-002" in html


def test_line_report_command(lot, capsys):
    _, js, _, tmp = lot
    assert main(["line", "report", "--runs-dir", str(tmp), "--lot", js["lot"]]) == 0
    path = Path(capsys.readouterr().out.strip())
    assert path.is_file() and "Yield by station" in path.read_text()


def _m(name, value, truth, iv, low, high, outcome, rule="guard-band"):
    return {"name": name, "value": value, "truth": truth, "interval": iv, "limits": {"low": low, "high": high},
            "rule": rule, "outcome": outcome, "u_low": None if iv is None else value - iv[0],
            "u_high": None if iv is None else iv[1] - value}


def test_expected_outcome_from_truth():
    inside = _m("tau_s", 300.0, 300.0, [299.0, 301.0], 250.0, 400.0, "PASS")
    near = _m("tau_s", 251.0, 251.5, [250.0, 252.0], 250.0, 400.0, "PASS")  # 1.5 inside, width 2: may be anything
    out = _m("tau_s", 200.0, 200.0, [199.0, 201.0], 250.0, 400.0, "FAIL")
    untruthed = _m("drift_after_dph", 6.0, None, None, None, 8.0, "MARGINAL", rule="value")
    assert expected_outcome({"measurements": [inside]})[0] == "PASS"
    assert expected_outcome({"measurements": [near]})[0] is None
    assert expected_outcome({"measurements": [inside, out]})[0] == "FAIL"
    assert expected_outcome({"measurements": [inside, untruthed]})[0] is None  # truth cannot say
    wrong = check_lot([{"serial": "A", "attempt": 1, "outcome": "FAIL", "measurements": [inside]},
                       {"serial": "B", "attempt": 1, "outcome": "MARGINAL", "measurements": [near]}])
    assert len(wrong) == 1 and wrong[0].startswith("A: FAIL, expected PASS")
