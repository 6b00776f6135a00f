"""Routing rules across commands and stations: a passed unit is not retested without a reason, a
failed one not without a rework code, max_attempts counts every attempt of the serial (database
and disk); limits naming what the sequence never measures are refused before scanning; FAIL,
MARGINAL (conditional), ERROR and ABORTED exit with distinct codes."""

import json
from pathlib import Path

import pytest

from bench.cli import main
from bench.line.cli import EXIT_ABORTED, EXIT_ERROR, EXIT_FAIL, EXIT_MARGINAL, EXIT_NOT_SAVED, exit_code

ROOT = Path(__file__).resolve().parents[1]
PASS_LIMITS = '[product]\nname="p"\n[limits.table_rate_dps]\nlow=99.5\nhigh=100.5\nrule="value"\n'
FAIL_LIMITS = '[product]\nname="p"\n[limits.table_rate_dps]\nlow=200\nhigh=300\nrule="value"\n'
# the simulated table holds 100 deg/s within 0.05: inside the marginal band above 99.9
MARGINAL_LIMITS = PASS_LIMITS + "marginal_high=99.9\n"


@pytest.fixture
def line(tmp_path, capsys):
    """`line run` of one unit against the given limits (and sequence), in one runs dir and database."""
    url = f"sqlite:///{tmp_path / 'line.sqlite'}"

    def run(serial, limits_text, *extra, seq="ci-spin", runs_dir=tmp_path):
        limits = tmp_path / f"limits-{abs(hash(limits_text))}.toml"
        limits.write_text(limits_text)
        code = main(["line", "run", seq, "--dut", serial, "--operator", "ann", "--yes", "--lot", "L1",
                     "--runs-dir", str(runs_dir), "--db", url, "--limits", str(limits), *extra])
        out, err = capsys.readouterr()
        return code, out, err

    return run


def test_a_passed_unit_needs_a_reason_to_be_tested_again(line):
    assert line("P1", PASS_LIMITS)[0] == 0
    code, _, err = line("P1", PASS_LIMITS)
    assert code == 2 and "unit P1 passed ci-spin (attempt 1 on station sim-hrg" in err and "--retest-reason" in err
    code, out, _ = line("P1", PASS_LIMITS, "--retest-reason", "customer return")
    assert code == 0 and "P1 attempt 2: PASS" in out


def test_a_failed_unit_needs_a_rework_code(line, tmp_path):
    assert line("F1", FAIL_LIMITS)[0] == EXIT_FAIL
    code, _, err = line("F1", PASS_LIMITS)
    assert code == 2 and "unit F1 failed ci-spin" in err and "--rework CODE" in err
    code, _, err = line("F1", PASS_LIMITS, "--rework", "bad\ncode")
    assert code == 2 and "rework code" in err
    code, out, _ = line("F1", PASS_LIMITS, "--rework", "rw-12")
    assert code == 0 and "F1 attempt 2: PASS" in out
    rec = json.loads((tmp_path / "line" / "L1" / "F1-a2.json").read_text())
    assert rec["routing"] == {"prior_attempts": 1, "rework": "RW-12", "retest_reason": None, "last_outcome": "FAIL"}


def test_max_attempts_holds_across_commands_and_stations(line, tmp_path):
    seq = tmp_path / "twice.toml"
    seq.write_text('[sequence]\nname="twice"\nstation="sim-hrg"\n[retest]\nmax_attempts=2\non=["MARGINAL"]\n'
                   '[[step]]\nprocedure="table-spin"\n[step.params]\nhold_s=0.5\n')
    code, out, _ = line("M1", MARGINAL_LIMITS, seq=str(seq))
    assert code == EXIT_MARGINAL and "M1 attempt 1: MARGINAL" in out and "M1 attempt 2: MARGINAL" in out
    other = tmp_path / "other-station.toml"  # another station, its own runs dir, the same line database
    other.write_text((ROOT / "bench" / "stations" / "sim-hrg.toml").read_text().replace('id = "sim-hrg"',
                                                                                      'id = "other"'))
    code, _, err = line("M1", MARGINAL_LIMITS, "--station", str(other), seq=str(seq), runs_dir=tmp_path / "b")
    assert code == 2 and "unit M1 has had 2 attempt(s) of twice (max_attempts 2)" in err
    code, out, _ = line("M1", PASS_LIMITS, "--station", str(other), "--rework", "RW-1", seq=str(seq),
                        runs_dir=tmp_path / "b")
    assert code == 0 and "M1 attempt 3: PASS" in out


def test_a_fail_is_not_retested_within_one_command(line, tmp_path):
    seq = tmp_path / "retest-fail.toml"
    seq.write_text('[sequence]\nname="rf"\nstation="sim-hrg"\n[retest]\nmax_attempts=3\non=["FAIL"]\n'
                   '[[step]]\nprocedure="table-spin"\n[step.params]\nhold_s=0.5\n')
    code, out, _ = line("F2", FAIL_LIMITS, seq=str(seq))
    assert code == EXIT_FAIL and "attempt 2" not in out  # a FAIL needs rework first


def test_limits_naming_what_the_sequence_never_measures_are_refused_before_scanning(line, tmp_path):
    code, _, err = line("T1", PASS_LIMITS + "[limits.tau_s]\nlow=250\nhigh=400\n")
    assert code == 2 and "[limits.tau_s] names a measurement no step of sequence 'ci-spin' measures" in err
    assert not (tmp_path / "line").exists() and not list(tmp_path.glob("*.h5"))


def test_outcomes_exit_with_distinct_codes(line):
    assert line("E0", PASS_LIMITS)[0] == 0
    assert line("E1", FAIL_LIMITS)[0] == EXIT_FAIL == 1
    assert line("E2", MARGINAL_LIMITS)[0] == EXIT_MARGINAL == 3
    code, out, _ = line("E3", PASS_LIMITS, "--fault", "table-estop@0.2")
    assert code == EXIT_ERROR == 4 and "E3 attempt 1: ERROR" in out
    rec = {"serial": "A", "outcome": "ABORTED"}
    assert exit_code([rec]) == EXIT_ABORTED == 5
    assert exit_code([{"serial": "A", "outcome": "PASS", "db_error": "down"}]) == EXIT_NOT_SAVED == 6
    assert exit_code([{"serial": "A", "outcome": "PASS"}, {"serial": "B", "outcome": "MARGINAL"}]) == 3
    assert len({0, EXIT_FAIL, 2, EXIT_MARGINAL, EXIT_ERROR, EXIT_ABORTED, EXIT_NOT_SAVED}) == 7
