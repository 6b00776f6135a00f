"""The line database under several stations at once: 8 processes run a short sequence against one
SQLite file and one PostgreSQL server; every record, measurement and run is counted, none lost."""

import json
import subprocess
import sys
from pathlib import Path

import pytest
from sqlalchemy import create_engine, func, select

from bench.line.db import LineDB
from bench.results.schema import runs

STATIONS, UNITS = 8, 1


#: sim-hrg with a 20 s table watchdog: eight stations' heartbeats on two loaded cores can starve for
#: the default 2 s and trip the table, which is the watchdog working, not what this test is about
STATION_TOML = (Path(__file__).parents[1] / "bench" / "stations" / "sim-hrg.toml").read_text().replace(
    'driver = "modbus-table"', 'driver = "modbus-table"\nwatchdog_s = 20.0')


def _stations(url, runs_dir):
    """Eight station processes at once, forked by one command once it has imported what a station
    runs (each its own process and connections; eight interpreters' imports would cost ~10 s of CPU)."""
    station = runs_dir / "sim-hrg-slow-watchdog.toml"
    station.write_text(STATION_TOML)
    p = subprocess.run([sys.executable, "-m", "bench.line.stations", url, str(runs_dir), "0", str(UNITS),
                        "--station-file", str(station), "--no-pdf", "--stations", str(STATIONS)],
                       capture_output=True, text=True, timeout=240)
    assert p.returncode == 0, p.stderr[-2000:]
    outs = [json.loads(line) for line in p.stdout.splitlines() if line.startswith("{")]
    assert sorted(o["station"] for o in outs) == list(range(STATIONS))
    assert len({o["pid"] for o in outs}) == STATIONS  # eight processes
    return outs


@pytest.mark.parametrize("engine", ["sqlite", "postgresql"])
def test_eight_stations_lose_nothing(engine, tmp_path, request):
    url = f"sqlite:///{tmp_path / 'line.sqlite'}" if engine == "sqlite" else request.getfixturevalue("pg_url")
    outs = _stations(url, tmp_path)
    want = {f"S{i}-{k}" for i in range(STATIONS) for k in range(UNITS)}
    assert {s for o in outs for s in o["serials"]} == want
    db = LineDB(url)
    try:
        attempts = db.attempts(lot="concurrent")
        assert len(attempts) == STATIONS * UNITS  # every record, once
        assert {a["serial"] for a in attempts} == want
        assert db.count() == (STATIONS * UNITS, STATIONS * UNITS)  # one limited measurement each
        assert all(a["outcome"] == "PASS" for a in attempts)
        records = db.records(lot="concurrent")
        run_ids = {r["run_id"] for rec in records for r in rec["runs"]}
        assert len(run_ids) == STATIONS * UNITS
    finally:
        db.close()
    eng = create_engine(url)
    with eng.connect() as conn:  # the runs are in the results store too, beside the line's tables
        assert conn.execute(select(func.count()).select_from(runs)).scalar_one() == STATIONS * UNITS
    eng.dispose()
    files = list(tmp_path.glob("st*/line/concurrent/*.json"))
    assert len(files) == STATIONS * UNITS  # and every JSON record on disk


def test_attempts_are_numbered_per_unit(tmp_path):
    db = LineDB(tmp_path / "line.sqlite")
    rec = {"serial": "U1", "lot": "L", "station": "s", "operator": "o", "sequence": "q", "software_version": "v",
           "started_at": "2026-01-01T00:00:00+00:00", "ended_at": "2026-01-01T00:01:00+00:00", "outcome": "PASS",
           "attempt": 1, "measurements": []}
    db.save(dict(rec))
    assert db.next_attempt("U1") == 2
    again = dict(rec)  # another station drew attempt 1 too: it becomes attempt 2, nothing is lost
    db.save(again)
    assert again["attempt"] == 2 and [a["attempt"] for a in db.attempts(serial="U1")] == [1, 2]
    db.close()


def test_line_schema_matches_declared_beside_the_results_store(store_url):
    from sqlalchemy import inspect, text

    from bench.line.schema import VERSION_TABLE, metadata
    from bench.results import ResultsStore

    store = ResultsStore(store_url)  # the results store's own chain, then the line's beside it
    db = LineDB(store_url)
    insp = inspect(db.engine)
    for table in metadata.sorted_tables:
        assert {c["name"] for c in insp.get_columns(table.name)} == {c.name for c in table.columns}, table.name
        indexes = {i["name"] for i in insp.get_indexes(table.name) if not i.get("duplicates_constraint")}
        assert indexes == {i.name for i in table.indexes}, table.name  # PostgreSQL lists UNIQUE as an index too
    with db.engine.connect() as conn:
        assert conn.execute(text(f"SELECT version_num FROM {VERSION_TABLE}")).scalar_one() == "line0002"
    assert store.revision() == ResultsStore.head()  # the run store's chain is untouched
    LineDB(store_url).close()  # re-opening an up-to-date database is a no-op
    db.close()
    store.close()
