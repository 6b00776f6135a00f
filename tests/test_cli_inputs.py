"""Bad inputs to the CLI end in one clear line and a non-zero exit, never "internal error" (issue 39):
a --limit SQLite cannot hold, HDF5 files from another program, params that are not JSON, station
ids, serials and operators with control characters; and the store commands do what their help says
(show a raw file, 95 % intervals, an empty store, re-analyses kept apart)."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest

from bench.cli import main
from bench.recorder import NotARunFile, RawDataError, Recorder, open_run
from bench.validation import ValidationError, check_label, printable


def _one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "internal error" not in err and "Traceback" not in err, err
    return lines[0]


@pytest.fixture(scope="module")
def recorded(tmp_path_factory) -> Path:
    """One short recorded run (its store and raw file) shared by the tests here."""
    root = tmp_path_factory.mktemp("recorded")
    assert main(["run", "table-spin", "--set", "hold_s=0.2", "--runs-dir", str(root / "runs"),
                 "--results", str(root / "results.sqlite"), "--json"]) == 0
    return root


def test_labels_are_checked_for_length_control_characters_and_nul():
    assert check_label("--dut", "SN-0042 ä") == "SN-0042 ä"
    assert check_label("--operator", "", allow_empty=True) == ""
    for bad, words in (("a\x00b", "NUL"), ("A\nB\x1b[31mRED", "U+000A"), ("x" * 65, "above the limit 64"),
                       ("", "is empty"), ("  ", "is empty")):
        with pytest.raises(ValidationError, match=re.escape(words)):
            check_label("--dut", bad)
    assert printable("A\nB\x1b[31mRED") == "A\\nB\\x1b[31mRED"


@pytest.mark.parametrize("args, words", [
    (["--dut", "A\nB\x1b[31mRED"], "--dut='A\\nB\\x1b[31mRED' holds a control character"),
    (["--dut", "S" * 10_000], "above the limit 64"),
    (["--operator", "ann\x00"], "(NUL)"),
])
def test_run_refuses_bad_serials_and_operators_before_anything_starts(tmp_path, capsys, monkeypatch, args, words):
    monkeypatch.chdir(tmp_path)
    assert main(["run", "table-spin", *args]) == 2
    assert words in _one_line(capsys.readouterr().err)
    assert not (tmp_path / "runs").exists()


def test_a_station_id_with_nul_is_refused_and_leaves_nothing(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    station = tmp_path / "nul.toml"
    station.write_text('[station]\nid = "a\\u0000b"\n[simulation]\npreset = "hrg"\n'
                       '[devices.table]\ndriver = "modbus-table"\n')
    assert main(["run", "table-spin", "--station", str(station)]) == 2
    assert "[station] id='a\\x00b' holds a control character (NUL)" in _one_line(capsys.readouterr().err)
    assert not (tmp_path / "runs").exists()


def test_a_run_attribute_hdf5_cannot_hold_leaves_no_reserve_or_stub(tmp_path):
    with pytest.raises(RawDataError, match="cannot be stored"):
        Recorder(tmp_path / "r.h5", attrs={"run_id": "x", "station_id": "a\x00b"})
    assert list(tmp_path.iterdir()) == []


def test_runs_limit_too_large_for_sqlite_and_an_empty_store(tmp_path, capsys):
    store = str(tmp_path / "results.sqlite")
    assert main(["runs", "--results", store, "--limit", "100000000000000000000"]) == 2
    assert "--limit=100000000000000000000 is above the limit 1000000" in _one_line(capsys.readouterr().err)
    assert main(["runs", "--results", store]) == 0
    out = capsys.readouterr()
    assert out.out == "" and "no runs yet in sqlite:///" in _one_line(out.err)


def _foreign(path: Path) -> Path:
    with h5py.File(path, "w") as f:
        f["x"] = np.arange(3)
    return path


def _bad_params(recorded: Path, path: Path) -> Path:
    shutil.copy(next((recorded / "runs").glob("*.h5")), path)
    with h5py.File(path, "a") as f:
        f.attrs["params"] = "{not json"
    return path


@pytest.mark.parametrize("command", ["analyze", "report", "show"])
def test_hdf5_files_that_are_not_runs_are_named_in_one_line(recorded, tmp_path, capsys, command):
    foreign, bad = _foreign(tmp_path / "other.h5"), _bad_params(recorded, tmp_path / "bad.h5")
    assert main([command, str(foreign)]) == 2
    said = _one_line(capsys.readouterr().err)
    assert "other.h5: not a gyrobench raw file (it has no streams, fits, log, measurements)" in said
    assert main([command, str(bad)]) == 2
    assert "bad.h5: attribute 'params' is not a JSON object: '{not json'" in _one_line(capsys.readouterr().err)
    with pytest.raises(NotARunFile):
        open_run(foreign)


def test_show_a_raw_file_with_intervals_and_reanalysis_kept_apart(recorded, capsys):
    raw = str(next((recorded / "runs").glob("*.h5")))
    store = str(recorded / "results.sqlite")
    assert main(["show", raw]) == 0
    out = capsys.readouterr().out
    assert "measurements (the run's own):" in out and "  95% [" in out and "limits [99.5, 100.5]" in out
    assert main(["analyze", "last", "--results", store]) == 0
    said = capsys.readouterr().out
    assert f"stored in sqlite:///{store} as this run's re-analysis (1 row(s)" in said
    assert main(["show", "last", "--results", store]) == 0
    shown = capsys.readouterr().out
    own, _, again = shown.partition("re-analysis (gyrobench analyze")
    assert own.count("table_rate_dps = ") == 1 and again.count("table_rate_dps = ") == 1
    assert main(["show", "last", "--results", store, "--json"]) == 0
    sources = [m["source"] for m in json.loads(capsys.readouterr().out)["measurements"]]
    assert sources == ["run", "analyze"]
    assert main(["report", "last", "--results", store]) == 0
    html = Path(capsys.readouterr().out.strip()).read_text()
    head, _, tail = html.partition("<h2>Re-analysis</h2>")
    assert tail and "table_rate_dps" in head.partition("<h2>Measurements</h2>")[2] and "table_rate_dps" in tail
    assert main(["analyze", "last", "--results", store, "--no-store"]) == 0
    assert "not stored (--no-store)" in capsys.readouterr().out


def test_show_spells_out_escapes_stored_before_labels_were_checked(recorded, tmp_path, capsys):
    raw = tmp_path / "esc.h5"
    shutil.copy(next((recorded / "runs").glob("*.h5")), raw)
    with h5py.File(raw, "a") as f:
        f.attrs["operator"] = "A\nB\x1b[31mRED"
    assert main(["show", str(raw)]) == 0
    out = capsys.readouterr().out
    assert "\x1b" not in out and "operator: A\\nB\\x1b[31mRED" in out


@pytest.mark.parametrize("body, words", [
    ("import sys\nsys.exit(0)\n", "it called sys.exit(0) while being imported"),
    ("import time\ntime.sleep(20)\n", "its import did not finish within 0.5 s"),
    ("raise RuntimeError('boom')\n", "loading it failed: RuntimeError: boom"),
])
def test_a_procedure_file_that_exits_hangs_or_raises_at_import_is_an_error(tmp_path, capsys, monkeypatch, body,
                                                                             words):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("GYROBENCH_IMPORT_TIMEOUT_S", "0.5")
    (tmp_path / "proc.py").write_text(body)
    assert main(["run", "proc.py"]) == 2
    assert words in _one_line(capsys.readouterr().err)
    assert not (tmp_path / "runs").exists()


def test_line_run_window_without_a_display_is_one_line_before_anything_opens(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    for name in ("DISPLAY", "WAYLAND_DISPLAY", "QT_QPA_PLATFORM"):
        monkeypatch.delenv(name, raising=False)
    code = main(["line", "run", "ci-spin", "--station", "sim-hrg-4", "--operator", "ann", "--dut", "A1",
                 "--dut", "A2", "--window", "--yes"])
    line = _one_line(capsys.readouterr().err)
    assert code == 2 and "line run --window: no display (DISPLAY / WAYLAND_DISPLAY unset)" in line
    assert "libxcb" not in line and not (tmp_path / "runs").exists()
    from bench.gui.app import window_unavailable

    assert window_unavailable("x", {"QT_QPA_PLATFORM": "offscreen"}) is None
    assert window_unavailable("x", {"DISPLAY": ":0"}) is None
    assert "QT_QPA_PLATFORM=xcb" in window_unavailable("x", {"QT_QPA_PLATFORM": "xcb"})


def test_a_raw_file_deleted_mid_run_is_reported_as_lost(tmp_path):
    import bench.engine.events as ev

    folder = tmp_path / "runs"
    rec = Recorder(folder / "r.h5", {"params": {"x": 1}, "run_id": "r", "procedure": "x"})
    t = np.arange(100) * 1e-3
    with pytest.raises(RawDataError) as err:
        for k in range(1000):  # a minute of data at most: the next flush meets the removed folder
            rec.on_event(ev.SampleBlock(run_id="r", t_sim_s=float(t[-1] + k * 0.1), stream="fpga", columns=("t_s", "v"),
                                        data=np.column_stack([t + k * 0.1, t])))
            if k == 20:
                shutil.rmtree(folder)
        rec.flush()
    text = str(err.value)
    assert "was deleted during the run: all of its recorded data is lost" in text and "is kept in" not in text
    assert f"its folder {folder} too" in text
    rec.close()


def test_a_store_file_deleted_while_open_is_named_not_called_read_only(tmp_path):
    from bench.results import ResultsStore

    store = ResultsStore(tmp_path / "results.sqlite")
    (tmp_path / "results.sqlite").unlink()
    text = str(store._fail(RuntimeError("attempt to write a readonly database")))
    assert f"its file {tmp_path / 'results.sqlite'} was deleted while open" in text and "readonly" not in text


def test_lockstep_data_is_flushed_every_bench_second(tmp_path, monkeypatch):
    """Blocks published as fast as a lockstep run makes them: a flush follows each bench second (a
    full disk or a kill loses at most a second and a block), not only each quarter wall second
    (which let a fast run leave 40 bench s unflushed, benchmarks/flush_cadence.py)."""
    import bench.engine.events as ev

    rec = Recorder(tmp_path / "r.h5", {"params": {}, "run_id": "r", "procedure": "x"})
    flushed: list[float] = []
    real = Recorder._flush
    monkeypatch.setattr(Recorder, "_flush", lambda self: (real(self), flushed.append(self._last_t)))
    block_s, t = 0.1, np.arange(100) * 1e-3
    for k in range(300):  # 30 bench s in a few wall ms
        rec.on_event(ev.SampleBlock(run_id="r", t_sim_s=(k + 1) * block_s, stream="fpga", columns=("t_s", "v"),
                                    data=np.column_stack([t + k * block_s, t])))
    rec.close()
    gaps = np.diff([0.0, *flushed[:-1]])  # the last is close's own flush
    assert len(flushed) >= 29 and gaps.max() <= 1.0 + block_s + 1e-9, gaps


BAD_STATION = """[station]
id = "a\\u0000b"
colour = "red"
[simulation]
preset = "hrg"
seed = -1
[devices.table]
driver = "modbus-table"
max_rate_dps = "fast"
[devices.frontend]
driver = "nope"
"""


def test_check_station_reports_every_problem_and_opens_nothing(tmp_path, capsys):
    path = tmp_path / "bad.toml"
    path.write_text(BAD_STATION)
    assert main(["check-station", str(path)]) == 2
    out = capsys.readouterr().out.splitlines()
    assert out[-1] == f"{path}: 5 problem(s)"
    for words in ("[station] colour: unknown key", "[station] id='a\\x00b' holds a control character (NUL)",
                  "[simulation] seed=-1 is below the limit 0", "[devices.table] max_rate_dps='fast' is not a number",
                  "[devices.frontend] driver='nope' is not one of"):
        assert sum(words in line for line in out[:-1]) == 1, (words, out)
    assert main(["check-station", "sim-hrg-4", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["problems"] == []
    assert main(["check-station", "sim-hrg"]) == 0
    assert "ok: station 'sim-hrg' (simulated), devices fpga, frontend, table" in capsys.readouterr().out
    assert main(["check-station", str(tmp_path / "none.toml")]) == 2
    assert "no such station file" in capsys.readouterr().out


def test_every_builtin_station_checks_clean():
    from bench.station_config import builtin_stations, station_problems

    assert {name: station_problems(path) for name, path in builtin_stations().items()} == \
        {name: [] for name in builtin_stations()}


def test_a_fault_for_a_device_the_station_lacks_is_one_line(tmp_path, capsys, monkeypatch):
    """StationError raised once the station is open (schedule_fault) is a known error, not "internal"."""
    monkeypatch.chdir(tmp_path)
    station = tmp_path / "no_frontend.toml"
    station.write_text('[station]\nid = "audit"\n[simulation]\npreset = "hrg"\n'
                       '[devices.table]\ndriver = "modbus-table"\n[devices.fpga]\ndriver = "fpga-link"\n')
    assert main(["run", "table-spin", "--set", "hold_s=0.2", "--station", str(station),
                 "--fault", "frontend-hang@1"]) == 2
    assert "--fault frontend-hang: station 'audit' has no frontend to fault" in _one_line(capsys.readouterr().err)
