"""Alembic environment: runs on the connection `ResultsStore` hands over (online only)."""

from __future__ import annotations

from alembic import context

from bench.results.schema import metadata

connection = context.config.attributes.get("connection")
if connection is None:  # pragma: no cover - the store always passes its connection
    raise RuntimeError("run migrations through bench.results.ResultsStore(url).upgrade()")
context.configure(connection=connection, target_metadata=metadata, render_as_batch=True)
with context.begin_transaction():
    context.run_migrations()
