"""The unit record: a real run of a short sequence judged against product limits, validated against
docs/unit_record.schema.json, and exported in OpenHTF's layout, checked against what OpenHTF's own
record classes write for the same test."""

import hashlib
import json
from pathlib import Path

import pytest

from bench.line.limits import load_limits
from bench.line.record import SCHEMA_PATH, to_openhtf
from bench.line.run import LineContext, run_unit
from bench.line.sequence import load_sequence

jsonschema = pytest.importorskip("jsonschema")


class Yes:
    def scan_serial(self):
        return "SN-1"

    def confirm(self, question):
        return True

    def show_outcome(self, serial, outcome, summary):
        self.shown = (serial, outcome, summary)


def _run(tmp_path, sequence, limits_text, serial="SN-1"):
    from bench.composition import load_station

    lim = tmp_path / "limits.toml"
    lim.write_text(limits_text)
    ctx = LineContext(load_sequence(sequence), load_limits(lim), "sim-hrg", "ann", tmp_path, lot="L7")
    return run_unit(ctx, lambda: load_station("sim-hrg"), serial, Yes())


@pytest.fixture(scope="module")
def spin_record(tmp_path_factory):
    """ci-spin judged by limits that also name tau_s, which table-spin never measures."""
    tmp = tmp_path_factory.mktemp("rec")
    text = ('[product]\nname="p"\n[limits.table_rate_dps]\nlow=99.5\nhigh=100.5\nrule="value"\nmarginal_high=99.9\n'
            '[limits.tau_s]\nlow=250\nhigh=400\n')
    (rec,) = _run(tmp, "ci-spin", text)
    return rec


def test_record_matches_schema_and_names_why(spin_record):
    schema = json.loads(SCHEMA_PATH.read_text())
    jsonschema.validate(spin_record, schema)
    jsonschema.validate(json.loads(Path(spin_record["record_file"]).read_text()), schema)  # as written
    by = {m["name"]: m for m in spin_record["measurements"]}
    rate = by["table_rate_dps"]
    # the simulated table holds 100 deg/s to better than 0.05: inside the marginal band above 99.9
    assert abs(rate["value"] - 100.0) < 0.05 and rate["rule"] == "value" and rate["outcome"] == "MARGINAL"
    assert by["tau_s"]["outcome"] == "ERROR" and by["tau_s"]["run_id"] is None  # named, never measured
    assert spin_record["outcome"] == "ERROR"  # the worst of MARGINAL and ERROR
    (run,) = spin_record["runs"]
    assert run["sha256"] == hashlib.sha256(Path(run["raw_file"]).read_bytes()).hexdigest()
    assert (spin_record["serial"], spin_record["lot"], spin_record["operator"], spin_record["attempt"]) == (
        "SN-1", "L7", "ann", 1)


def test_schema_rejects_a_broken_record(spin_record):
    schema = json.loads(SCHEMA_PATH.read_text())
    bad = json.loads(json.dumps(spin_record))
    bad["measurements"][0]["outcome"] = "OK"
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(bad, schema)
    bad = json.loads(json.dumps(spin_record))
    del bad["serial"]
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(bad, schema)


def test_stop_on_fail_skips_the_rest(tmp_path):
    seq = tmp_path / "two.toml"
    seq.write_text('[sequence]\nname="two"\n[[step]]\nprocedure="table-spin"\n[step.params]\nhold_s=0.3\n'
                   '[[step]]\nprocedure="table-spin"\n[step.params]\nhold_s=0.3\n')
    (rec,) = _run(tmp_path, str(seq), '[product]\nname="p"\n[limits.table_rate_dps]\nlow=200\nhigh=300\n')
    assert rec["outcome"] == "FAIL" and rec["stopped_by"] == "FAIL" and len(rec["runs"]) == 1
    assert [m["outcome"] for m in rec["measurements"]] == ["FAIL", "SKIPPED"]


def _openhtf_record(record):
    """The same test built with OpenHTF's own classes and written by its json_factory."""
    from openhtf.core import measurements as hm
    from openhtf.core import test_record as tr
    from openhtf.output.callbacks import json_factory

    from bench.line.record import HTF_MEAS_OUTCOME, HTF_TEST_OUTCOME, _cond, _millis, openhtf_metadata

    meta = openhtf_metadata(record)
    rec = tr.TestRecord(dut_id=record["serial"], station_id=record["station"],
                        start_time_millis=_millis(record["started_at"]), end_time_millis=_millis(record["ended_at"]),
                        outcome=tr.Outcome[HTF_TEST_OUTCOME[record["outcome"]]], metadata=meta,
                        marginal=record["outcome"] == "MARGINAL")
    for i, run in enumerate(record["runs"], 1):
        meas = {}
        for m in record["measurements"]:
            if m["run_id"] != run["run_id"]:
                continue
            hm_m = hm.Measurement(m["name"])
            lim, marg = m["limits"], m.get("marginal") or {}
            if lim and (lim["low"] is not None or lim["high"] is not None):
                hm_m = hm_m.in_range(lim["low"], lim["high"], marg.get("low"), marg.get("high"))
            iv = m["interval"]
            hm_m = hm_m.doc(f"{m['outcome']}{_cond(m)} by rule {m['rule'] or 'none'}; unit {m['unit'] or '-'}; "
                            "95% interval " + ("none" if iv is None else f"[{iv[0]}, {iv[1]}]"))
            if m["value"] is not None:
                hm_m.measured_value.set(m["value"])
            hm_m.outcome = hm.Outcome[HTF_MEAS_OUTCOME[m["outcome"]]]
            meas[m["name"]] = hm_m
        outcomes = {m["outcome"] for m in record["measurements"] if m["run_id"] == run["run_id"]}
        rec.add_phase_record(tr.PhaseRecord(
            i, run["procedure"], tr.CodeInfo.uncaptured(), measurements=meas,
            start_time_millis=_millis(run["started_at"]), end_time_millis=_millis(run["ended_at"]),
            outcome=tr.PhaseOutcome["FAIL" if "FAIL" in outcomes else "PASS"], marginal="MARGINAL" in outcomes))
    return json.loads(json.dumps(json_factory.convert_test_record_to_json(rec)))


def test_openhtf_layout_is_what_openhtf_writes(spin_record):
    pytest.importorskip("openhtf")
    ours = to_openhtf(spin_record)
    assert ours == _openhtf_record(spin_record)
    (phase,) = ours["phases"]
    m = phase["measurements"]["table_rate_dps"]
    assert m["validators"] == ["99.5 <= x <= Marginal:99.9 <= 100.5"] and m["outcome"] == "PASS"
    assert ours["outcome"] == "ERROR" and ours["dut_id"] == "SN-1" and ours["station_id"] == "sim-hrg"


def test_a_run_that_errors_is_recorded_and_retested(tmp_path):
    """The table's emergency stop in the first attempt: the run ends ERROR in the safe state, the
    unit's record says ERROR (its limited measurement never measured), and the retest policy runs a
    second attempt, which passes; both records are kept."""
    from bench.composition import load_station

    seq = tmp_path / "retest.toml"
    seq.write_text('[sequence]\nname="retest"\n[retest]\nmax_attempts=2\non=["ERROR"]\n'
                   '[[step]]\nprocedure="table-spin"\n[step.params]\nhold_s=2.0\n')
    lim = tmp_path / "limits.toml"
    lim.write_text('[product]\nname="p"\n[limits.table_rate_dps]\nlow=99.5\nhigh=100.5\n')
    ctx = LineContext(load_sequence(seq), load_limits(lim), "sim-hrg", "ann", tmp_path, lot="L8")
    opened = []

    def open_station():
        st = load_station("sim-hrg")
        if not opened:
            st.schedule_fault("table-estop", 1.0)
        opened.append(st)
        return st

    first, second = run_unit(ctx, open_station, "SN-2", Yes())
    assert first["outcome"] == "ERROR" and first["runs"][0]["outcome"] == "ERROR"
    assert first["runs"][0]["safe_state"] is True and "safety trip" in first["runs"][0]["end_reason"]
    assert [m["outcome"] for m in first["measurements"]] == ["ERROR"]
    assert second["outcome"] == "PASS" and (first["attempt"], second["attempt"]) == (1, 2)
    assert all(Path(r["record_file"]).is_file() for r in (first, second))


def test_a_record_the_database_refuses_is_kept_and_imported_later(tmp_path, capsys):
    """The database down at the end of a unit: the signed record is kept on disk (the error beside
    it, the record file itself never rewritten), `line import` takes it once; a retest of the unit
    meanwhile is attempt 2 in a new file, never over the kept one."""
    from bench.cli import main
    from bench.composition import load_station
    from bench.line import LineError
    from bench.line.db import LineDB
    from bench.line.integrity import Signer, generate_key

    class Down:
        def save(self, record):
            raise LineError("line database postgresql://line/db: connection refused")

    key, pub = generate_key(tmp_path / "station.key")
    lim = tmp_path / "limits.toml"
    lim.write_text('[product]\nname="p"\n[limits.table_rate_dps]\nlow=99.5\nhigh=100.5\n')
    ctx = LineContext(load_sequence("ci-spin"), load_limits(lim), "sim-hrg", "ann", tmp_path, db=Down(), lot="L9",
                      signer=Signer(key))
    (rec,) = run_unit(ctx, lambda: load_station("sim-hrg"), "SN-3", Yes())
    kept = Path(rec["record_file"])
    text = kept.read_text()
    on_disk = json.loads(text)
    assert "connection refused" in rec["db_error"] and on_disk["outcome"] == "PASS" and "db_error" not in on_disk
    assert "connection refused" in kept.with_suffix(".db_error.txt").read_text()
    jsonschema.validate(on_disk, json.loads(SCHEMA_PATH.read_text()))
    (again,) = run_unit(ctx, lambda: load_station("sim-hrg"), "SN-3", Yes())  # the database still down
    assert again["attempt"] == 2 and again["record_file"] != str(kept) and kept.read_text() == text
    url = str(tmp_path / "line.sqlite")
    for added in (1, 0):  # imported once; a second import finds it there
        assert main(["line", "import", str(kept), "--db", url, "--key", str(pub)]) == 0
        assert f"imported {added} record(s)" in capsys.readouterr().out
    db = LineDB(url)
    assert [(a["serial"], a["attempt"], a["outcome"]) for a in db.attempts()] == [("SN-3", 1, "PASS")]
    db.close()


def test_openhtf_export_keeps_marginal_its_kind_and_the_checksums():
    """Issue 32: the export kept neither a MARGINAL's kind nor the record's checksums."""
    import copy

    from cert_record import RECORD

    rec = copy.deepcopy(RECORD)
    rec.update(lot="L1", limits_sha256="a" * 64, sequence_sha256="b" * 64,
               integrity={"sha256": "c" * 64, "signature": "d" * 128})
    drift = next(m for m in rec["measurements"] if m["name"] == "drift_after_dph")
    drift["condition"] = "conditional pass"
    htf = to_openhtf(rec)
    assert htf["marginal"] is True and htf["outcome"] == "PASS"
    meta = htf["metadata"]
    assert meta["gyrobench_outcome"] == "MARGINAL" and meta["conditions"] == {"drift_after_dph": "conditional pass"}
    assert meta["checksums"] == {"record_sha256": "c" * 64, "signature": "d" * 128, "limits_sha256": "a" * 64,
                                 "sequence_sha256": "b" * 64,
                                 "raw_files": {"r-damp": {"file": "runs/a.h5", "sha256": "0" * 64},
                                               "r-fd": {"file": "runs/b.h5", "sha256": "1" * 64}}}
    doc = htf["phases"][0]["measurements"]["drift_after_dph"]["docstring"]
    assert doc.startswith("MARGINAL (conditional pass) by rule guard-band")
