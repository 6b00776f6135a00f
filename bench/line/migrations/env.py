"""Alembic environment of the line database: its own chain and version table (line_alembic_version)
beside the results store's, on the connection `LineDB` hands over."""

from __future__ import annotations

from alembic import context

from bench.line.schema import VERSION_TABLE, metadata

connection = context.config.attributes.get("connection")
if connection is None:  # pragma: no cover - LineDB always passes its connection
    raise RuntimeError("run the line's migrations through bench.line.db.LineDB(url).upgrade()")
context.configure(connection=connection, target_metadata=metadata, render_as_batch=True,
                  version_table=VERSION_TABLE)
with context.begin_transaction():
    context.run_migrations()
