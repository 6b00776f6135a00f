"""`gyrobench run` opens the results store in a thread while the station opens (issue 36): the run
is still stored, and a store that cannot be opened at all is one line and exit 1 with the station
closed (no simulator or link thread left)."""

from __future__ import annotations

import json
import threading

import pytest

from bench.cli import main
from bench.cli.common import CliError, StoreOpening

SHORT = ["run", "table-spin", "--set", "hold_s=0.1", "--json"]


def test_store_opening_gives_the_store_or_raises_its_error_in_the_caller(tmp_path) -> None:
    store = StoreOpening(str(tmp_path / "r.sqlite"), offline_ok=True).result()
    assert store.open_error is None and store.revision() == store.head()
    (tmp_path / "file").write_text("")
    with pytest.raises(CliError, match="cannot be opened"):
        StoreOpening(str(tmp_path / "file" / "r.sqlite"), offline_ok=True).result()


def test_a_run_is_stored_with_the_store_opened_alongside_the_station(tmp_path, capsys) -> None:
    from bench.results import ResultsStore

    db = tmp_path / "r.sqlite"
    code = main([*SHORT, "--runs-dir", str(tmp_path / "runs"), "--results", str(db)])
    js = json.loads(capsys.readouterr().out)
    assert code == 0 and js["outcome"] == "PASS"
    row = ResultsStore(db).get_run(js["run_id"])
    assert row["outcome"] == "PASS" and row["raw_file"] == js["raw_file"]


def test_a_store_that_cannot_be_opened_is_one_line_and_the_station_is_closed(tmp_path, capsys) -> None:
    (tmp_path / "file").write_text("")
    before = {t.ident for t in threading.enumerate()}
    code = main([*SHORT, "--runs-dir", str(tmp_path / "runs"), "--results", str(tmp_path / "file" / "r.sqlite")])
    out, err = capsys.readouterr()
    assert code == 1 and out == ""
    lines = err.splitlines()
    assert len(lines) == 1 and "results store" in lines[0] and "cannot be opened" in lines[0], err
    new = [t for t in threading.enumerate() if t.ident not in before]
    for t in new:  # a connection's handler sees its peer go just after the close returned
        t.join(timeout=10.0)
    left = [t.name for t in new if t.is_alive()]
    assert left == [], left  # the simulators' servers and the links' readers ended with the station's close
    assert not list((tmp_path / "runs").glob("*.h5"))  # nothing ran
