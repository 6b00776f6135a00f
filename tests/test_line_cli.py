"""`gyrobench line run`: a headless unit end to end, and one clear line for what is missing."""

import json
from pathlib import Path

from bench.cli import main


def test_line_run_headless(tmp_path, capsys):
    code = main(["line", "run", "ci-spin", "--dut", "SN-9", "--operator", "ann", "--yes", "--lot", "L1",
                 "--runs-dir", str(tmp_path), "--json"])
    out = capsys.readouterr().out
    (rec,) = json.loads(out.strip().splitlines()[-1])
    assert code == 0 and rec["outcome"] == "PASS" and rec["station"] == "sim-hrg" and rec["attempt"] == 1
    cert = tmp_path / "line" / "L1" / "SN-9-a1.certificate.html"  # every unit gets its certificate
    assert rec["documents"]["certificate"] == str(cert) and "SN-9" in cert.read_text()
    from bench.line.certificate import pdf_available

    if pdf_available():  # and its PDF beside it (issue 32)
        assert Path(rec["documents"]["certificate_pdf"]).read_bytes()[:5] == b"%PDF-"
    # the same unit again (a passed unit: with a reason): attempt 2 in the line database
    code = main(["line", "run", "ci-spin", "--dut", "SN-9", "--operator", "ann", "--yes", "--lot", "L1",
                 "--runs-dir", str(tmp_path), "--json", "--retest-reason", "audit sample"])
    (rec,) = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert code == 0 and rec["attempt"] == 2
    # and its export in OpenHTF's layout
    assert main(["line", "export", rec["record_file"]]) == 0
    assert json.loads(capsys.readouterr().out)["dut_id"] == "SN-9"


def _err(capsys, argv, monkeypatch=None):
    code = main(argv)
    err = capsys.readouterr().err.strip()
    assert "Traceback" not in err and len(err.splitlines()) == 1, err
    return code, err


def test_line_run_refuses_what_it_cannot_ask(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr("sys.stdin.isatty", lambda: False, raising=False)
    base = ["line", "run", "ci-spin", "--operator", "ann", "--runs-dir", str(tmp_path)]
    code, err = _err(capsys, base)
    assert code == 2 and "give --dut SERIAL" in err
    code, err = _err(capsys, base + ["--dut", "X1"])
    assert code == 2 and "give --yes" in err
    code, err = _err(capsys, ["line", "run", "ci-spin", "--operator", " ", "--dut", "X", "--yes"])
    assert code == 2 and "--operator NAME is required" in err
    bad = tmp_path / "bad.toml"
    bad.write_text('[sequence]\nname="b"\n[[step]]\nprocedure="table-spin"\n[step.params]\nrate_dps=5000\n')
    code, err = _err(capsys, ["line", "run", str(bad), "--operator", "a", "--dut", "X", "--yes"])
    assert code == 2 and "rate_dps=5000 deg/s is above the limit 1000 deg/s" in err
    code, err = _err(capsys, ["line", "run", "ci-spin", "--operator", "a", "--dut", "X", "--yes",
                              "--limits", str(tmp_path / "none.toml")])
    assert code == 2 and "no such limits file" in err


def test_line_run_refuses_a_station_that_does_not_fit(tmp_path, capsys):
    code, err = _err(capsys, ["line", "run", "eol-mems", "--station", "sim-hrg", "--operator", "a", "--dut", "X",
                              "--yes", "--runs-dir", str(tmp_path)])
    assert code == 2 and "[[step]] #1 mems-sweep" in err and "sim-hrg" in err
