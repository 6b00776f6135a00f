"""What is typed into the line is checked before anything runs: serials, lots and operators against
the product's formats and length limits, no control characters, a lot never a path; the
certificate escapes what it shows."""

import pytest

from bench.cli import main
from bench.line import LineError
from bench.line.certificate import render_html
from bench.line.inputs import check_lot, check_operator, check_serial


@pytest.mark.parametrize("bad", ["../../x", "/tmp/abs", "..", ".hidden", "a/b", "L\x00", "L\nX", "x" * 65])
def test_a_lot_is_a_name_never_a_path(bad):
    with pytest.raises(LineError, match="lot .* is not valid"):
        check_lot(bad)
    assert check_lot("L-2026.11_a") == "L-2026.11_a" and check_lot("") == ""


@pytest.mark.parametrize("bad", ["A\nB\x1b[31mRED", "A\x00B", "A" * 41, "", "SN 1"])
def test_a_serial_with_escapes_nul_or_too_long_is_refused(bad):
    with pytest.raises(LineError, match="serial .* is not valid"):
        check_serial(bad)


def test_the_products_format_decides():
    fmt = "HRG-[0-9]{6}"
    assert check_serial(" hrg-000123 ", fmt) == "HRG-000123"
    with pytest.raises(LineError, match=r"does not match the format HRG-\[0-9\]\{6\}"):
        check_serial("HRG-12", fmt)


@pytest.mark.parametrize("bad", ["<b>" * 30, "ann\x1b[31m", "a\u202eb", "x\x00"])
def test_an_operator_is_printable_and_short(bad):
    with pytest.raises(LineError, match="operator .* is not valid"):
        check_operator(bad)
    assert check_operator("Ann O'Neil") == "Ann O'Neil"


def _refused(capsys, tmp_path, *extra):
    argv = ["line", "run", "ci-spin", "--yes", "--runs-dir", str(tmp_path), *extra]
    code = main(argv)
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert not (tmp_path / "line").exists() and not list(tmp_path.glob("*.h5"))  # nothing ran
    return err


def test_line_run_refuses_bad_input_before_anything_runs(tmp_path, capsys):
    assert "lot '../../x' is not valid" in _refused(capsys, tmp_path, "--dut", "SN1", "--operator", "a",
                                                    "--lot", "../../x")
    assert "lot '/tmp/x' is not valid" in _refused(capsys, tmp_path, "--dut", "SN1", "--operator", "a",
                                                   "--lot", "/tmp/x")
    err = _refused(capsys, tmp_path, "--dut", "A\nB\x1b[31mRED", "--operator", "a")
    assert "\x1b" not in err and "\\x1b" in err  # shown escaped, never raw
    assert "operator" in _refused(capsys, tmp_path, "--dut", "SN1", "--operator", "x" * 10_000)
    limits = tmp_path / "fmt.toml"
    limits.write_text('[product]\nname="p"\nserial_format="HRG-[0-9]{6}"\n'
                      '[limits.table_rate_dps]\nlow=99.5\nhigh=100.5\n')
    assert "does not match the format" in _refused(capsys, tmp_path, "--dut", "SN1", "--operator", "a",
                                                   "--limits", str(limits))


def test_certificate_escapes_what_it_shows():
    record = {"serial": "SN-1", "attempt": 1, "operator": "<script>alert(4)</script>", "lot": "<b>L</b>",
              "outcome": "PASS", "measurements": [], "runs": [], "sequence": "s", "station": "st"}
    html = render_html(record)
    assert "<script>alert(4)</script>" not in html and "&lt;script&gt;alert(4)&lt;/script&gt;" in html
    assert "<b>L</b>" not in html


def test_a_bad_format_in_the_limits_file_is_one_clear_message(tmp_path):
    from bench.line.limits import load_limits

    path = tmp_path / "bad.toml"
    path.write_text('[product]\nname="p"\nserial_format="HRG-[0-9"\n[limits.table_rate_dps]\nlow=1\n')
    with pytest.raises(LineError, match=r"\[product\] serial_format='HRG-\[0-9' is not a regular expression"):
        load_limits(path)


def test_verify_refuses_a_lot_that_is_a_path(tmp_path, capsys):
    assert main(["line", "verify", "../../etc", "--runs-dir", str(tmp_path)]) == 2
    assert "lot '../../etc' is not valid" in capsys.readouterr().err
