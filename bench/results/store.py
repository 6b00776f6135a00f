"""The results store: runs, DUTs, measurements and truth, through SQLAlchemy Core.

`ResultsStore(url)` takes a SQLAlchemy URL (`sqlite:///runs/results.sqlite`, the default, or
`postgresql+psycopg://user@host/db` on a production line) or a plain file path, and brings
the schema to the newest migration on open.
"""

from __future__ import annotations

import datetime as _dt
import math
from pathlib import Path
from typing import Any

from alembic import command
from alembic.config import Config
from alembic.runtime.migration import MigrationContext
from alembic.script import ScriptDirectory
from sqlalchemy import create_engine, delete, event, insert, select
from sqlalchemy.engine import Engine

from .schema import measurements, run_duts, runs, truth

DEFAULT_PATH = Path("runs") / "results.sqlite"
MIGRATIONS = Path(__file__).resolve().parent / "migrations"


def to_url(url_or_path: str | Path | None) -> str:
    """A SQLAlchemy URL from a URL or a SQLite file path (default runs/results.sqlite)."""
    if url_or_path is None:
        url_or_path = DEFAULT_PATH
    text = str(url_or_path)
    if "://" in text:
        return text
    path = Path(text)
    path.parent.mkdir(parents=True, exist_ok=True)
    return f"sqlite:///{path}"


def _f(x: Any) -> float | None:
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


def _now() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat()


def _alembic_config() -> Config:
    cfg = Config()
    cfg.set_main_option("script_location", str(MIGRATIONS))
    return cfg


class ResultsStore:
    """Indexes runs and their measurements; the same code for SQLite and PostgreSQL."""

    def __init__(self, url: str | Path | None = None, *, upgrade: bool = True) -> None:
        self.url = to_url(url)
        self.engine: Engine = create_engine(self.url)
        if self.engine.dialect.name == "sqlite":
            event.listen(self.engine, "connect", _sqlite_pragmas)
        if upgrade:
            self.upgrade()

    def upgrade(self, revision: str = "head") -> None:
        cfg = _alembic_config()
        with self.engine.begin() as conn:
            cfg.attributes["connection"] = conn
            command.upgrade(cfg, revision)

    def revision(self) -> str | None:
        with self.engine.connect() as conn:
            return MigrationContext.configure(conn).get_current_revision()

    @staticmethod
    def head() -> str | None:
        return ScriptDirectory.from_config(_alembic_config()).get_current_head()

    def close(self) -> None:
        self.engine.dispose()

    # --- writing -------------------------------------------------------------------------
    def save_run(self, rec: Any) -> None:
        """Insert (or replace) a finished run with its DUTs, measurements and truth."""
        row = {
            "run_id": rec.run_id,
            "procedure": rec.procedure,
            "station_id": rec.station_id,
            "simulated": bool(rec.simulated),
            "outcome": rec.outcome,
            "end_reason": rec.end_reason,
            "safe_state": bool(rec.safe_state),
            "failed_step": rec.failed_step,
            "started_at": rec.started_at,
            "finished_at": rec.finished_at,
            "simulated_s": _f(rec.simulated_s),
            "wall_s": _f(rec.wall_s),
            "raw_file": rec.raw_file,
            "software_version": rec.software_version,
            "operator": rec.operator,
            "seed": rec.seed,
            "params": rec.params,
            "safe_detail": rec.safe_detail,
        }
        with self.engine.begin() as conn:
            for table in (measurements, truth, run_duts):
                conn.execute(delete(table).where(table.c.run_id == rec.run_id))
            conn.execute(delete(runs).where(runs.c.run_id == rec.run_id))
            conn.execute(insert(runs), [row])
            if rec.duts:
                conn.execute(
                    insert(run_duts), [{"run_id": rec.run_id, "slot": i, "serial": s} for i, s in enumerate(rec.duts)]
                )
            if rec.truth:
                conn.execute(
                    insert(truth), [{"run_id": rec.run_id, "name": k, "value": _f(v)} for k, v in rec.truth.items()]
                )
            self._insert_results(conn, rec.run_id, rec.measurements, "run")

    def save_analysis(self, run_id: str, results: list[Any]) -> None:
        """Add the measurements of a re-analysis (`gyrobench analyze`), replacing an earlier one."""
        with self.engine.begin() as conn:
            conn.execute(
                delete(measurements).where((measurements.c.run_id == run_id) & (measurements.c.source == "analyze"))
            )
            self._insert_results(conn, run_id, results, "analyze")

    @staticmethod
    def _insert_results(conn, run_id: str, results: list[Any], source: str) -> None:
        rows = []
        now = _now()
        for r in results:
            lim = r.limits
            rows.append(
                {
                    "run_id": run_id,
                    "name": r.name,
                    "dut": r.dut,
                    "value": _f(r.value),
                    "unit": r.unit,
                    "ci95_low": None if r.ci95 is None else _f(r.ci95[0]),
                    "ci95_high": None if r.ci95 is None else _f(r.ci95[1]),
                    "low": None if lim is None else _f(lim.low),
                    "high": None if lim is None else _f(lim.high),
                    "marginal_low": None if lim is None else _f(lim.marginal_low),
                    "marginal_high": None if lim is None else _f(lim.marginal_high),
                    "outcome": r.outcome,
                    "source": source,
                    "created_at": now,
                }
            )
        if rows:
            conn.execute(insert(measurements), rows)

    # --- reading -------------------------------------------------------------------------
    def list_runs(self, *, limit: int = 50, procedure: str | None = None, station_id: str | None = None) -> list[dict]:
        """Newest first."""
        q = select(runs).order_by(runs.c.started_at.desc()).limit(limit)
        if procedure:
            q = q.where(runs.c.procedure == procedure)
        if station_id:
            q = q.where(runs.c.station_id == station_id)
        with self.engine.connect() as conn:
            return [dict(r._mapping) for r in conn.execute(q)]

    def resolve(self, run: str) -> str:
        """A full run id from an id, a unique prefix, or "last"; KeyError if none or ambiguous."""
        with self.engine.connect() as conn:
            if run in ("last", "latest"):
                row = conn.execute(select(runs.c.run_id).order_by(runs.c.started_at.desc()).limit(1)).first()
                if row is None:
                    raise KeyError("the results store has no runs yet")
                return row[0]
            ids = [r[0] for r in conn.execute(select(runs.c.run_id).where(runs.c.run_id.like(f"{run}%")).limit(3))]
        if len(ids) == 1:
            return ids[0]
        if not ids:
            raise KeyError(f"no run {run!r} in {self.url}")
        raise KeyError(f"run {run!r} is ambiguous: {ids} ...")

    def get_run(self, run: str) -> dict[str, Any]:
        """The run row with its `duts`, `measurements` (list of dicts) and `truth`."""
        run_id = self.resolve(run)
        with self.engine.connect() as conn:
            row = dict(conn.execute(select(runs).where(runs.c.run_id == run_id)).one()._mapping)
            row["duts"] = [
                r.serial
                for r in conn.execute(select(run_duts).where(run_duts.c.run_id == run_id).order_by(run_duts.c.slot))
            ]
            row["measurements"] = [
                dict(r._mapping)
                for r in conn.execute(
                    select(measurements).where(measurements.c.run_id == run_id).order_by(measurements.c.id)
                )
            ]
            row["truth"] = {r.name: r.value for r in conn.execute(select(truth).where(truth.c.run_id == run_id))}
        return row


def _sqlite_pragmas(dbapi_conn, _record) -> None:
    cur = dbapi_conn.cursor()
    cur.execute("PRAGMA foreign_keys=ON")
    cur.execute("PRAGMA busy_timeout=10000")
    cur.close()
