"""A fresh results store built at once: the newest schema (`schema.metadata.create_all`) and
alembic's version table stamped at the head, instead of running every migration in turn (each
test's store and each first command in a new runs directory paid the migrations and alembic's
imports).  `tests/test_fresh_store.py` checks that the built schema is the migrated one, on SQLite
and PostgreSQL, so the two never drift."""

from __future__ import annotations

from sqlalchemy import Column, MetaData, PrimaryKeyConstraint, String, Table, insert, inspect
from sqlalchemy.engine import Connection

from .schema import metadata

VERSION_TABLE = "alembic_version"

# the table alembic itself creates to hold the revision (alembic.runtime.migration, its defaults)
version_table = Table(
    VERSION_TABLE,
    MetaData(),
    Column("version_num", String(32), nullable=False),
    PrimaryKeyConstraint("version_num", name="alembic_version_pkc"),
)


def is_fresh(conn: Connection) -> bool:
    """Whether none of the store's tables (nor alembic's version table) exist yet on this connection."""
    names = set(inspect(conn).get_table_names())
    return not names & ({VERSION_TABLE} | set(metadata.tables))


def build_fresh(conn: Connection, head: str) -> None:
    """The newest schema and the head revision, in the caller's transaction (under its migration lock)."""
    metadata.create_all(conn, checkfirst=False)
    version_table.create(conn, checkfirst=False)
    conn.execute(insert(version_table).values(version_num=head))
