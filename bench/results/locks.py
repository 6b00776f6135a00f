"""Schema migrations under a lock, so that processes opening a fresh store at once do not race:
a flock on a file beside a SQLite database, a PostgreSQL advisory lock held by the migrating
transaction."""

from __future__ import annotations

import contextlib
import fcntl
import os
from collections.abc import Iterator
from pathlib import Path

from sqlalchemy import text
from sqlalchemy.engine import Connection, Engine

# pg_advisory_xact_lock key shared by every gyrobench store on a server ("gyrobnch" in ASCII)
PG_MIGRATION_LOCK = 0x6779726F626E6368


def sqlite_file(engine: Engine) -> Path | None:
    """The database file of a SQLite engine; None for an in-memory database or another engine."""
    if engine.dialect.name != "sqlite":
        return None
    db = engine.url.database
    if not db or db == ":memory:" or db.startswith("file::memory:"):
        return None
    if db.startswith("file:"):  # a URI filename (sqlite:///file:path?mode=ro&uri=true)
        db = db[len("file:") :]
    return Path(db)


@contextlib.contextmanager
def file_lock(path: Path) -> Iterator[bool]:
    """Hold an exclusive flock on `path` (created if needed); yields False when the file cannot be
    made (a read-only directory, where nobody can create the store either)."""
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
    except OSError:
        yield False
        return
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield True
    finally:
        os.close(fd)  # closing releases the lock


@contextlib.contextmanager
def migrating_connection(engine: Engine) -> Iterator[Connection]:
    """A connection in a transaction that holds the store's migration lock until it ends."""
    db = sqlite_file(engine)
    outer = file_lock(db.with_name(db.name + ".lock")) if db is not None else contextlib.nullcontext()
    with outer, engine.begin() as conn:
        if engine.dialect.name == "postgresql":
            conn.execute(text("SELECT pg_advisory_xact_lock(:key)"), {"key": PG_MIGRATION_LOCK})
        yield conn
