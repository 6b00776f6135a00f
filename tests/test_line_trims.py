"""Trims as a gated last step (issue 32): a PASS unit's compensation goes into its FPGA's NVM at the
end of the sequence, read back, its unit id checked and the loaded file's hash in the record; a unit
that did not pass is not trimmed; `fpga load` by hand refuses a unit that did not pass or another
unit's NVM unless an override reason is given (and then logs it); the trims take the estimate with
the narrowest interval."""

from __future__ import annotations

import copy
import hashlib
import json
from pathlib import Path
from types import SimpleNamespace

from cert_record import RECORD

from bench.line.compensation import from_record, load, unit_id
from bench.line.limits import load_limits
from bench.line.run import LineContext, finish_record
from bench.line.sequence import load_sequence
from bench.line.trims import load_trims, pass_gate, write_unit_trims
from drivers.fpga import FpgaLink
from simulators.fpga import serve_fpga
from simulators.physics.params import preset
from simulators.world import World

PASSED = {**copy.deepcopy(RECORD), "outcome": "PASS"}


def _served():
    server = serve_fpga(World(preset("hrg"), seed=1))
    return server, FpgaLink(server.url, timeout_s=2.0).connect()


def test_a_pass_unit_is_trimmed_read_back_and_its_file_hashed(tmp_path):
    server, link = _served()
    try:
        out = write_unit_trims(link, PASSED, tmp_path / "u.compensation.toml")
        assert out["written"] and "error" not in out
        assert out["sha256"] == hashlib.sha256((tmp_path / "u.compensation.toml").read_bytes()).hexdigest()
        assert out["nvm"]["valid"] and out["nvm"]["match"] and out["nvm"]["commits"] == 1
        assert int(link.read_register("TRIM_UNIT_ID")) == unit_id("HRG-2611-0042") == int(out["unit_id"], 16)
        assert out["read_back"] == link.read_trims()
        assert out["nvm_unit_before"] == "000000000000"
    finally:
        link.close()
        server.stop()


def test_a_unit_that_did_not_pass_is_not_trimmed(tmp_path):
    server, link = _served()
    try:
        for outcome in ("FAIL", "MARGINAL", "ERROR"):
            out = write_unit_trims(link, {**PASSED, "outcome": outcome}, tmp_path / "u.toml")
            assert out == {"written": False, "reason": f"unit {outcome}: trims are written for PASS units only"}
        assert link.nvm_status()["commits"] == 0 and not (tmp_path / "u.toml").exists()
    finally:
        link.close()
        server.stop()


def test_nvm_of_another_unit_is_not_overwritten(tmp_path):
    server, link = _served()
    try:
        load_trims(link, from_record({**PASSED, "serial": "HRG-OTHER"}).trims())
        out = write_unit_trims(link, PASSED, tmp_path / "u.toml")
        assert not out["written"] and "another unit" in out["error"]
        assert int(link.read_register("TRIM_UNIT_ID")) == unit_id("HRG-OTHER")
        assert link.nvm_status()["commits"] == 1
    finally:
        link.close()
        server.stop()


def _ctx(tmp_path):
    seq = load_sequence("eol-hrg")
    assert seq.write_trims
    return LineContext(seq, load_limits("hrg"), "sim-hrg", "ada", tmp_path, lot="L1")


def _finish(ctx, station, measurements):
    return finish_record(ctx, station, "HRG-2611-0042", 1, "2026-11-28T00:00:00+00:00", [], measurements,
                         {(m["name"], m["procedure"]) for m in measurements}, None)


def _all_pass_measurements():
    lims = load_limits("hrg")
    out = []
    for lim in lims.limits:
        lo = lim.low if lim.low is not None else 0.0
        hi = lim.high if lim.high is not None else lo * 2 + 1
        v = 0.5 * (lo + hi)
        out.append({"name": lim.name, "procedure": lim.procedure or "hrg-free-decay", "run_id": "r1", "value": v,
                    "unit": lim.unit or "", "interval": [v, v], "limits": {"low": lim.low, "high": lim.high},
                    "rule": "value", "outcome": "PASS", "u_low": None, "u_high": None, "note": ""})
    return out + [m for m in PASSED["measurements"] if m["name"] in ("theta_tau_deg", "theta_w_deg")]


def test_the_line_writes_the_trims_last_for_pass_and_not_for_fail(tmp_path):
    server, link = _served()
    station = SimpleNamespace(id="sim-hrg", devices={"fpga": link}, simulated=True)
    try:
        rec = _finish(_ctx(tmp_path), station, _all_pass_measurements())
        assert rec["outcome"] == "PASS" and rec["trims"]["written"], rec["trims"]
        assert rec["trims"]["file"] == rec["documents"]["compensation"]
        assert rec["trims"]["sha256"] == hashlib.sha256(Path(rec["trims"]["file"]).read_bytes()).hexdigest()
        assert rec["trims"]["sha256"] == json.loads(Path(rec["record_file"]).read_text())["trims"]["sha256"]
        assert link.nvm_status()["commits"] == 1 and "trims in NVM" in rec["summary"]
        failed = _all_pass_measurements()
        failed[0] = {**failed[0], "outcome": "FAIL"}
        rec2 = finish_record(_ctx(tmp_path), station, "HRG-2", 1, "2026-11-28T00:00:00+00:00", [], failed,
                             {(m["name"], m["procedure"]) for m in failed}, None)
        assert rec2["outcome"] == "FAIL" and not rec2["trims"]["written"]
        assert link.nvm_status()["commits"] == 1
    finally:
        link.close()
        server.stop()


def test_a_trims_write_that_fails_makes_the_unit_error(tmp_path):
    class Broken:
        def nvm_status(self):
            raise OSError("link dropped")

    station = SimpleNamespace(id="sim-hrg", devices={"fpga": Broken()}, simulated=True)
    rec = _finish(_ctx(tmp_path), station, _all_pass_measurements())
    assert rec["outcome"] == "ERROR" and "link dropped" in rec["trims"]["error"] and "link dropped" in rec["summary"]


def test_the_trims_take_the_narrowest_interval_and_say_so():
    damp = {"name": "theta_tau_deg", "procedure": "hrg-damping", "run_id": "d", "value": 25.0, "unit": "deg",
            "interval": [23.0, 27.0]}
    fd = {"name": "theta_tau_deg", "procedure": "hrg-free-decay", "run_id": "f", "value": 24.9, "unit": "deg",
          "interval": [24.75, 25.05]}
    c = from_record({"serial": "U1", "measurements": [damp, fd]}).coefficients["theta_tau_deg"]
    assert (c.procedure, c.value) == ("hrg-free-decay", 24.9)
    assert c.basis == "narrowest 95 % interval: hrg-free-decay width 0.3 (over hrg-damping width 4)"
    c = from_record({"serial": "U1", "measurements": [{**damp, "interval": [24.95, 25.05]}, fd]}).coefficients[
        "theta_tau_deg"]
    assert c.procedure == "hrg-damping"


def test_pass_gate_reads_the_last_attempt_of_the_sequence():
    a = [{"serial": "U", "attempt": 1, "sequence": "eol-hrg", "station": "s", "outcome": "PASS"},
         {"serial": "U", "attempt": 2, "sequence": "eol-hrg", "station": "s", "outcome": "FAIL"}]
    assert pass_gate(a[:1], "U", "eol-hrg") is None
    assert pass_gate(a, "U", "eol-hrg") == ("unit U's last attempt (a2, sequence eol-hrg, station s) is FAIL; "
                                           "trims are loaded for PASS units only")
    assert "no attempt" in pass_gate([], "U", "eol-hrg")


def test_fpga_load_by_hand_is_gated_and_an_override_is_logged(tmp_path, capsys):
    from bench.cli import main
    from bench.line.record import write_new_record

    station = tmp_path / "st.toml"
    text = open("bench/stations/sim-hrg.toml").read().replace('id = "sim-hrg"', 'id = "nvm-hrg"')
    station.write_text(text + f'nvm_file = "{tmp_path / "fpga.nvm"}"\n')
    runs = tmp_path / "runs"
    comp = from_record(RECORD).write(tmp_path / "comp.toml")
    base = ["fpga", "load", str(comp), "--station", str(station), "--runs-dir", str(runs)]
    assert main(base) == 2  # no record of the unit
    assert "has no attempt by sequence eol-hrg" in capsys.readouterr().err
    write_new_record({**copy.deepcopy(RECORD), "outcome": "FAIL"}, runs / "line" / "L1")
    assert main(base) == 2
    assert "is FAIL; trims are loaded for PASS units only" in capsys.readouterr().err
    assert main([*base, "--override-reason", "engineering sample, QA-77", "--operator", "ada", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["override"]["reason"] == "engineering sample, QA-77"
    log = [json.loads(x) for x in (runs / "line" / "fpga_overrides.jsonl").read_text().splitlines()]
    assert [(e["serial"], e["reason"], e["operator"]) for e in log] == [("HRG-2611-0042", "engineering sample, QA-77",
                                                                          "ada")]
    # another unit's file onto that NVM: refused (its own PASS record does not help)
    other = {**copy.deepcopy(RECORD), "serial": "HRG-9", "outcome": "PASS"}
    write_new_record(other, runs / "line" / "L1")
    comp2 = from_record(other).write(tmp_path / "comp2.toml")
    assert main(["fpga", "load", str(comp2), "--station", str(station), "--runs-dir", str(runs)]) == 2
    assert "holds the trims of another unit" in capsys.readouterr().err
    assert load(comp2).serial == "HRG-9"


def test_a_sequence_that_writes_trims_is_refused_on_a_station_without_fpga(tmp_path, capsys):
    from bench.cli import main

    seq = tmp_path / "seq.toml"
    seq.write_text('[sequence]\nname = "t"\nlimits = "ci-spin"\n[trims]\nwrite = true\n[[step]]\n'
                   'procedure = "table-spin"\n')
    station = tmp_path / "no-fpga.toml"
    station.write_text(open("bench/stations/sim-hrg.toml").read().split("[devices.fpga]")[0])
    code = main(["line", "run", str(seq), "--station", str(station), "--operator", "ada", "--dut", "U1", "--yes",
                 "--runs-dir", str(tmp_path / "runs")])
    assert code == 2 and "[trims] write = true needs an FPGA to hold the trims" in capsys.readouterr().err


def test_line_run_eol_hrg_leaves_the_trims_in_the_units_nvm(tmp_path, capsys):
    """The issue's reproduction: `fpga show` after `line run eol-hrg` said "NVM empty ... 0 commits"."""
    from bench.cli import main

    station = tmp_path / "st.toml"
    text = open("bench/stations/sim-hrg.toml").read().replace('id = "sim-hrg"', 'id = "nvm-hrg"')
    station.write_text(text + f'nvm_file = "{tmp_path / "fpga.nvm"}"\n')
    code = main(["line", "run", "eol-hrg", "--station", str(station), "--operator", "ada", "--dut", "HRG-000042",
                 "--yes", "--lot", "L1", "--runs-dir", str(tmp_path / "runs"), "--json"])
    records = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert len(records) == 1, [(r["outcome"], r.get("end_reason"), r.get("failed_step")) for r in records]
    (rec,) = records
    assert code == 0 and rec["outcome"] == "PASS" and rec["trims"]["written"]
    chosen = rec["trims"]["chosen"]
    assert chosen["delta_inv_tau_per_s"]["procedure"] == chosen["theta_tau_deg"]["procedure"] == "hrg-free-decay"
    assert main(["fpga", "show", "--station", str(station), "--json"]) == 0
    shown = json.loads(capsys.readouterr().out)
    assert shown["nvm"]["valid"] and shown["nvm"]["match"] and shown["nvm"]["commits"] == 1
    assert shown["trims"] == rec["trims"]["read_back"]
    assert int(shown["trims"]["TRIM_UNIT_ID"]) == unit_id("HRG-000042")
    assert shown["trims"]["TRIM_FILE_ID"] == int(rec["trims"]["file_id"], 16)
    assert load(rec["trims"]["file"]).serial == "HRG-000042"
