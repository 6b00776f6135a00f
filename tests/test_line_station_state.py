"""Station calibration and the daily golden unit (issue 32): a station past a calibration due date
refuses line runs saying which and since when; a golden unit whose simulated truth differs from its
reference locks the station until an unlock with a reason; one within its limit does not."""

from __future__ import annotations

import datetime as dt
import json

import pytest

from bench.cli import main
from bench.devices import StationError
from bench.line.station_state import overdue, read_log, refusal
from bench.station_config import load_config

SIM = open("bench/stations/sim-hrg.toml").read()


def _station(tmp_path, calibration: str = "") -> str:
    path = tmp_path / "st.toml"
    path.write_text(SIM + calibration)
    return str(path)


def test_calibration_dates_are_read_and_checked(tmp_path):
    cfg = load_config(_station(tmp_path, '\n[calibration]\ntable = 2026-03-01\nfrontend = "2027-01-31"\n'))
    assert cfg.calibration == {"table": dt.date(2026, 3, 1), "frontend": dt.date(2027, 1, 31)}
    assert overdue(cfg.calibration, dt.date(2026, 11, 28)) == ["table (due 2026-03-01, 272 days ago)"]
    assert overdue(cfg.calibration, dt.date(2026, 3, 1)) == []  # due today: still in calibration
    with pytest.raises(StationError, match=r"\[calibration\] reference_1 = 'soon' is not a date"):
        load_config(_station(tmp_path, '\n[calibration]\nreference_1 = "soon"\n'))


def test_a_station_past_its_calibration_refuses_line_runs(tmp_path, capsys):
    st = _station(tmp_path, "\n[calibration]\ntable = 2020-01-31\nfrontend = 2099-01-01\nreference_1 = 2021-06-30\n")
    code = main(["line", "run", "ci-spin", "--station", st, "--operator", "ada", "--dut", "U1", "--yes",
                 "--runs-dir", str(tmp_path / "runs")])
    err = capsys.readouterr().err
    assert code == 2
    assert "refuses line runs: calibration past due: table (due 2020-01-31, " in err
    assert "reference_1 (due 2021-06-30, " in err and "frontend" not in err
    assert not (tmp_path / "runs" / "line" / "no-lot").exists()  # nothing ran
    code = main(["line", "simulate", "--sequence", "ci-spin", "--station", st, "--units", "1",
                 "--runs-dir", str(tmp_path / "runs")])
    assert code == 2 and "calibration past due: table (due 2020-01-31" in capsys.readouterr().err


def _golden(tmp_path, value: float) -> str:
    path = tmp_path / f"golden-{value}.toml"
    path.write_text(f'[golden]\nserial = "GOLD-1"\n[reference.table_rate_dps]\nvalue = {value}\nlimit = 0.05\n'
                    'unit = "deg/s"\n')
    return str(path)


def test_a_golden_unit_drifted_past_its_limit_locks_the_station_until_a_reasoned_unlock(tmp_path, capsys):
    runs = str(tmp_path / "runs")
    st = _station(tmp_path)
    # the simulated table turns at 100 deg/s (within 0.01): a reference of 100.3 is a drift of -0.3
    assert main(["line", "golden", "ci-spin", "--golden", _golden(tmp_path, 100.3), "--station", st,
                 "--operator", "ada", "--runs-dir", runs, "--json"]) == 1
    out = json.loads(capsys.readouterr().out)
    [row] = out["drifts"]
    assert row["drift"] == pytest.approx(-0.3, abs=0.01) and not row["ok"]
    assert "table_rate_dps drifted" in out["locked"]
    assert "locked since" in refusal({}, runs, "sim-hrg")
    code = main(["line", "run", "ci-spin", "--station", st, "--operator", "ada", "--dut", "U1", "--yes",
                 "--runs-dir", runs])
    assert code == 2 and "golden unit GOLD-1: table_rate_dps drifted" in capsys.readouterr().err
    assert main(["line", "unlock", "--station", st, "--reason", "", "--operator", "ada", "--runs-dir", runs]) == 2
    capsys.readouterr()
    assert main(["line", "unlock", "--station", st, "--reason", "reference re-measured, NCR-12", "--operator", "bo",
                 "--runs-dir", runs]) == 0
    assert "unlocked (reference re-measured, NCR-12)" in capsys.readouterr().out
    assert refusal({}, runs, "sim-hrg") is None
    # the same unit against a reference its truth matches: recorded, no lock
    assert main(["line", "golden", "ci-spin", "--golden", _golden(tmp_path, 100.0), "--station", st,
                 "--operator", "ada", "--runs-dir", runs, "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["locked"] is None
    log = read_log(runs, "sim-hrg")
    assert [e["event"] for e in log] == ["golden", "lock", "unlock", "golden"]
    assert log[2]["reason"] == "reference re-measured, NCR-12" and log[2]["operator"] == "bo"
    assert [e["held"] for e in log if e["event"] == "golden"] == [False, True]
