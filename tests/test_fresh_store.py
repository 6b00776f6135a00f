"""A fresh results store is built at once (the newest schema and alembic's head stamped: fresh.py)
instead of migrated step by step: its schema must be the migrated one, table by table, column by
column (types, nullability, defaults), keys, indexes, constraints, triggers and sequences, on
SQLite and PostgreSQL, so the two ways can never drift apart."""

from __future__ import annotations

import json
import uuid

import pytest
from sqlalchemy import create_engine, insert, inspect, text

from bench.results import ResultsStore
from bench.results.schema import runs, truth
from bench.results.store import head_revision


def _schema(url: str) -> dict:
    """Everything a schema declares, as plain data (the schema's own name left out)."""
    engine = create_engine(url)
    try:
        with engine.connect() as conn:
            insp = inspect(conn)
            tables = {}
            for name in sorted(insp.get_table_names()):
                tables[name] = {
                    "columns": [{k: str(c.get(k)) for k in ("name", "type", "nullable", "default", "autoincrement")}
                                for c in insp.get_columns(name)],
                    "primary_key": insp.get_pk_constraint(name),
                    "foreign_keys": sorted(insp.get_foreign_keys(name), key=lambda f: json.dumps(f, default=str)),
                    "indexes": sorted(insp.get_indexes(name), key=lambda i: str(i["name"])),
                    "unique": sorted(insp.get_unique_constraints(name), key=lambda u: str(u["name"])),
                    "checks": sorted(insp.get_check_constraints(name), key=lambda c: str(c["name"])),
                }
            if engine.dialect.name == "sqlite":
                extra = conn.execute(text("SELECT type, name, tbl_name, sql FROM sqlite_master "
                                          "WHERE type IN ('trigger', 'view') ORDER BY name")).all()
            else:
                extra = conn.execute(text(
                    "SELECT 'trigger', t.tgname, c.relname, replace(pg_get_triggerdef(t.oid), current_schema(), 'S') "
                    "FROM pg_trigger t JOIN pg_class c ON c.oid = t.tgrelid "
                    "JOIN pg_namespace n ON n.oid = c.relnamespace "
                    "WHERE NOT t.tgisinternal AND n.nspname = current_schema() "
                    "UNION ALL SELECT 'sequence', sequence_name, data_type, start_value || ' ' || increment "
                    "FROM information_schema.sequences WHERE sequence_schema = current_schema() "
                    "UNION ALL SELECT 'view', table_name, '', view_definition FROM information_schema.views "
                    "WHERE table_schema = current_schema() ORDER BY 1, 2")).all()
            version = conn.execute(text("SELECT version_num FROM alembic_version")).scalars().all()
    finally:
        engine.dispose()
    return json.loads(json.dumps({"tables": tables, "other": [list(r) for r in extra], "version": version},
                                 default=str))


@pytest.fixture
def two_stores(store_url, tmp_path):
    """Two empty stores on one engine: two SQLite files, or two schemas on the PostgreSQL server."""
    if store_url.startswith("sqlite"):
        yield store_url, f"sqlite:///{tmp_path / 'migrated.sqlite'}"
        return
    base, _, _ = store_url.partition("options=")
    schema = f"t_{uuid.uuid4().hex[:12]}"
    admin = create_engine(base.rstrip("?&"), isolation_level="AUTOCOMMIT")
    with admin.connect() as conn:
        conn.execute(text(f"CREATE SCHEMA {schema}"))
    try:
        yield store_url, f"{base}options=-csearch_path%3D{schema}"
    finally:
        with admin.connect() as conn:
            conn.execute(text(f"DROP SCHEMA {schema} CASCADE"))
        admin.dispose()


def test_a_fresh_store_built_at_once_is_the_migrated_schema(two_stores):
    built_url, migrated_url = two_stores
    built = ResultsStore(built_url)  # fresh: built at once
    migrated = ResultsStore(migrated_url, upgrade=False)
    migrated.upgrade(ResultsStore.head())  # a named revision: every migration in turn, by alembic
    assert built.revision() == migrated.revision() == ResultsStore.head() == head_revision()
    built.close()
    migrated.close()
    a, b = _schema(built_url), _schema(migrated_url)
    assert set(a["tables"]) == {"alembic_version", "runs", "run_duts", "measurements", "truth"}
    for name in a["tables"]:
        assert a["tables"][name] == b["tables"][name], name
    assert a == b


def test_a_store_at_an_older_revision_is_still_migrated(store_url):
    """Only an empty store is built at once: one at an older revision keeps its rows and migrates."""
    old = ResultsStore(store_url, upgrade=False)
    old.upgrade("0003")
    with old.engine.begin() as conn:
        conn.execute(insert(runs).values(run_id="r", procedure="p", station_id="s", outcome="PASS",
                                         started_at="2026-01-01T00:00:00+00:00", params={}))
        conn.execute(insert(truth).values(run_id="r", name="x", value=1.5))
    old.close()
    store = ResultsStore(store_url)
    assert store.revision() == ResultsStore.head()
    with store.engine.connect() as conn:
        assert conn.execute(text("SELECT value FROM truth WHERE run_id = 'r'")).scalar_one() == 1.5
        assert "run_token" in {c["name"] for c in inspect(conn).get_columns("runs")}
    store.close()


