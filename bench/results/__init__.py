"""The results store: runs, measurements and outcomes (SQLite by default, PostgreSQL by URL),
one SQLAlchemy Core schema with versioned alembic migrations shipped in the package.  Its names
load on first use, so `bench.results.redact` costs no database import."""

from __future__ import annotations

from typing import Any

__all__ = ["DEFAULT_PATH", "ResultsStore", "StoreError", "to_url"]


def __getattr__(name: str) -> Any:
    if name in __all__:
        from . import store

        return getattr(store, name)
    raise AttributeError(f"module 'bench.results' has no attribute {name!r}")
