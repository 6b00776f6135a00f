"""The results store: migrations build the schema the code declares; runs, DUTs, measurements,
truth and re-analyses round-trip; run ids resolve by prefix."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from sqlalchemy import inspect

from bench.engine import Limits, Result, RunRecord
from bench.results import ResultsStore, to_url
from bench.results.schema import metadata
from bench.results.store import head_revision


def _record(run_id: str, started: str, outcome: str = "PASS", duts=(), seed: int = 7) -> RunRecord:
    return RunRecord(
        run_id=run_id,
        procedure="table-spin",
        params={"rate_dps": 100.0},
        station_id="sim-hrg",
        simulated=True,
        outcome=outcome,
        end_reason="completed",
        safe_state=True,
        measurements=[
            Result("tau_s", 2.5, "s", ci95=(2.4, 2.6), limits=Limits(1, 4, 1.5, 3.5)),
            Result("bias_dph", float("nan"), "deg/h", dut="SN2"),
        ],
        truth={"tau_s": 2.51},
        simulated_s=3.0,
        wall_s=0.2,
        started_at=started,
        software_version="0.1.0",
        operator="ana",
        duts=list(duts),
        seed=seed,
    )


def test_migrated_schema_matches_declared_tables(store_url):
    store = ResultsStore(store_url)
    assert store.revision() == ResultsStore.head() == "0004"
    insp = inspect(store.engine)
    for table in metadata.sorted_tables:
        cols = {c["name"] for c in insp.get_columns(table.name)}
        assert cols == {c.name for c in table.columns}, table.name
        idx = {i["name"] for i in insp.get_indexes(table.name)}
        assert idx == {i.name for i in table.indexes}, table.name
    ResultsStore(store_url)  # re-opening an up-to-date store is a no-op


def test_head_read_from_the_migration_files_is_alembics_head(tmp_path):
    assert head_revision() == ResultsStore.head()
    (tmp_path / "0001_a.py").write_text('revision = "0001"\ndown_revision = None\n')
    (tmp_path / "0002_b.py").write_text("revision = '0002'\ndown_revision = '0001'\n")
    assert head_revision(tmp_path) == "0002"
    (tmp_path / "0003_c.py").write_text('revision = "0003"\ndown_revision = "0001"\n')
    assert head_revision(tmp_path) is None  # two heads: the store then asks alembic


_OPEN_TWICE = """
import sys
from bench.results import ResultsStore
ResultsStore(sys.argv[1]).close()
print("alembic" in sys.modules)
"""


def test_an_up_to_date_store_opens_without_alembic(tmp_path):
    """Every command that opens the store paid alembic's ~0.3 s of imports (issue 36): only a
    store that needs a migration imports it now.  A fresh store is built at once without it
    (fresh.py); a store at an older revision is migrated by alembic; then neither imports it."""
    root = Path(__file__).resolve().parents[1]

    def opens(db: Path) -> list[str]:
        return subprocess.run([sys.executable, "-c", _OPEN_TWICE, str(db)], cwd=root, capture_output=True,
                              text=True, check=True).stdout.split()

    fresh, old = tmp_path / "fresh.sqlite", tmp_path / "old.sqlite"
    assert [opens(fresh), opens(fresh)] == [["False"], ["False"]]
    ResultsStore(old, upgrade=False).upgrade("0003")
    assert [opens(old), opens(old)] == [["True"], ["False"]]
    assert ResultsStore(fresh).revision() == ResultsStore(old).revision() == ResultsStore.head()


def test_sqlite_path_becomes_url(tmp_path):
    assert to_url(tmp_path / "r.sqlite") == f"sqlite:///{tmp_path / 'r.sqlite'}"
    assert to_url("postgresql://u@h/db") == to_url("postgres://u@h/db") == "postgresql+psycopg://u@h/db"


def test_roundtrip_runs_measurements_truth_duts(store_url):
    store = ResultsStore(store_url)
    store.save_run(_record("20260101-000000-aaaaaa", "2026-01-01T00:00:00+00:00", duts=["SN1", "SN2"]))
    store.save_run(_record("20260102-000000-bbbbbb", "2026-01-02T00:00:00+00:00", outcome="FAIL"))
    rows = store.list_runs()
    assert [r["run_id"] for r in rows] == ["20260102-000000-bbbbbb", "20260101-000000-aaaaaa"]
    assert store.resolve("last") == "20260102-000000-bbbbbb"
    run = store.get_run("20260101")
    assert run["duts"] == ["SN1", "SN2"] and run["truth"] == {"tau_s": 2.51} and run["params"] == {"rate_dps": 100.0}
    m = {x["name"]: x for x in run["measurements"]}
    assert m["tau_s"]["outcome"] == "PASS" and m["tau_s"]["marginal_high"] == 3.5 and m["tau_s"]["ci95_low"] == 2.4
    assert m["bias_dph"]["value"] is None and m["bias_dph"]["dut"] == "SN2"
    store.save_analysis(run["run_id"], [Result("tau_s", 2.49, "s")])
    store.save_analysis(run["run_id"], [Result("tau_s", 2.48, "s")])  # replaces the earlier re-analysis
    srcs = [(x["source"], x["value"]) for x in store.get_run(run["run_id"])["measurements"]]
    assert srcs.count(("analyze", 2.48)) == 1 and ("analyze", 2.49) not in srcs
    # saving a run again replaces it whole
    store.save_run(_record("20260101-000000-aaaaaa", "2026-01-01T00:00:00+00:00", outcome="ERROR"))
    again = store.get_run("20260101-000000-aaaaaa")
    assert again["outcome"] == "ERROR" and again["duts"] == [] and len(again["measurements"]) == 2


def test_unknown_and_ambiguous_run_ids(store_url):
    store = ResultsStore(store_url)
    with pytest.raises(KeyError, match="no runs yet"):
        store.resolve("last")
    store.save_run(_record("20260101-000000-aaaaaa", "2026-01-01T00:00:00+00:00"))
    store.save_run(_record("20260101-000000-aaaabb", "2026-01-01T00:00:01+00:00"))
    with pytest.raises(KeyError, match="ambiguous"):
        store.resolve("20260101")
    with pytest.raises(KeyError, match="no run 'zzz'"):
        store.get_run("zzz")


def test_63_bit_seed_keeps_its_row(store_url):
    """A station accepts seeds up to 2**63 - 1; PostgreSQL's INTEGER column lost such a run."""
    store = ResultsStore(store_url)
    for seed in (3_000_000_000, 2**63 - 1):
        store.save_run(_record(f"20260101-000000-{seed % 999999:06d}", "2026-01-01T00:00:00+00:00", seed=seed))
        assert store.get_run(f"20260101-000000-{seed % 999999:06d}")["seed"] == seed
