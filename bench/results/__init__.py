"""The results store: runs, measurements and outcomes (SQLite by default, PostgreSQL by URL),
one SQLAlchemy Core schema with versioned alembic migrations shipped in the package."""

from .store import DEFAULT_PATH, ResultsStore, StoreError, to_url

__all__ = ["DEFAULT_PATH", "ResultsStore", "StoreError", "to_url"]
