"""The results store: runs, DUTs, measurements and truth, through SQLAlchemy Core.

`ResultsStore(url)` takes a SQLAlchemy URL (`sqlite:///runs/results.sqlite`, the default, or
`postgresql+psycopg://user@host/db` on a production line) or a plain file path, and brings
the schema to the newest migration on open (under a lock: see `locks.py`).

A run's row is written when it starts (`begin_run`: outcome RUNNING, host, process id and a
heartbeat kept fresh by a daemon thread) and replaced when it ends (`finish_run`).  A RUNNING
row whose run is gone (`liveness.is_interrupted`) becomes INTERRUPTED when the store is listed.
A record the store cannot take is kept in a spool (`spool.py`) and submitted by `sync`.
"""

from __future__ import annotations

import datetime as _dt
import math
import os
from pathlib import Path
from typing import Any

from alembic import command
from alembic.config import Config
from alembic.runtime.migration import MigrationContext
from alembic.script import ScriptDirectory
from sqlalchemy import create_engine, delete, event, insert, select, text, update
from sqlalchemy.engine import Engine, make_url
from sqlalchemy.exc import SQLAlchemyError

from bench.engine.measurement import INTERRUPTED, RUNNING

from .liveness import HEARTBEAT_S, Heartbeat, host_name, is_interrupted, now_iso, process_alive
from .locks import migrating_connection, sqlite_file
from .schema import measurements, run_duts, runs, truth
from .spool import Spool

DEFAULT_PATH = Path("runs") / "results.sqlite"
MIGRATIONS = Path(__file__).resolve().parent / "migrations"
POSTGRES_EXTRA = "pip install 'gyrobench[postgres]'"
PG_NOW_ISO = """SELECT to_char(clock_timestamp() AT TIME ZONE 'UTC', 'YYYY-MM-DD"T"HH24:MI:SS.US"+00:00"')"""


class StoreError(Exception):
    """The results store cannot be opened, reached or written; the message is one line for a user."""


# what a store that cannot be reached or written raises (OSError: e.g. a full disk for a lock file)
DB_ERRORS = (SQLAlchemyError, OSError)
STORE_ERRORS = (StoreError, *DB_ERRORS)


def to_url(url_or_path: str | Path | None) -> str:
    """A SQLAlchemy URL from a URL or a SQLite file path (default runs/results.sqlite); a plain
    `postgresql://` URL gets the psycopg (v3) driver that `gyrobench[postgres]` installs."""
    if url_or_path is None:
        url_or_path = DEFAULT_PATH
    text = str(url_or_path)
    for plain in ("postgresql://", "postgres://"):
        if text.startswith(plain):
            return "postgresql+psycopg://" + text[len(plain) :]
    if "://" in text:
        return text
    path = Path(text)
    path.parent.mkdir(parents=True, exist_ok=True)
    return f"sqlite:///{path}"


def describe_error(exc: BaseException) -> str:
    """The first line of what the database said (no SQL, no traceback)."""
    inner = getattr(exc, "orig", None) or exc
    lines = [ln.strip() for ln in str(inner).splitlines() if ln.strip()]
    return lines[0] if lines else type(inner).__name__


def _f(x: Any) -> float | None:
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


def _alembic_config() -> Config:
    cfg = Config()
    cfg.set_main_option("script_location", str(MIGRATIONS))
    return cfg


def _interrupted(row: dict[str, Any]) -> dict[str, Any]:
    """The fields that turn a RUNNING row whose run is gone into INTERRUPTED (raw file kept)."""
    beat = (row.get("heartbeat_at") or "")[:19] or "never"
    return {
        "outcome": INTERRUPTED,
        "end_reason": f"interrupted: the run ended without a record (host {row.get('host')}, process "
        f"{row.get('pid')}, last heartbeat {beat})",
        "finished_at": row.get("heartbeat_at"),
        "safe_state": False,
    }


class ResultsStore:
    """Indexes runs and their measurements; the same code for SQLite and PostgreSQL.

    `offline_ok=True` lets a store that cannot be reached now be opened anyway (writes then fail,
    and `begin_run` / `finish_run` spool); otherwise opening raises StoreError."""

    def __init__(
        self,
        url: str | Path | None = None,
        *,
        upgrade: bool = True,
        offline_ok: bool = False,
        spool_dir: str | Path | None = None,
    ) -> None:
        self.url = to_url(url)
        try:
            self.engine: Engine = create_engine(self.url)
        except ImportError as exc:  # the dialect's driver is not installed
            name = getattr(exc, "name", None) or describe_error(exc)
            hint = f"; {POSTGRES_EXTRA}" if self.url.startswith("postgres") else ""
            raise StoreError(f"results store {self.display_url}: its driver {name!r} is not installed{hint}") from None
        if self.engine.dialect.name == "sqlite":
            event.listen(self.engine, "connect", _sqlite_pragmas)
        db = sqlite_file(self.engine)
        if spool_dir is None:
            spool_dir = (db.parent if db is not None else DEFAULT_PATH.parent) / "spool"
        self.spool = Spool(spool_dir)
        self._beats: dict[str, Heartbeat] = {}
        self.heartbeat_s = HEARTBEAT_S
        self._ready = not upgrade
        self.open_error: str | None = None
        if upgrade:
            try:
                self._ensure_ready()
            except StoreError as exc:
                if not offline_ok:
                    raise
                self.open_error = str(exc)
            else:
                self._reap_quietly()

    @property
    def display_url(self) -> str:
        """The URL without its password, for messages."""
        try:
            return make_url(self.url).render_as_string(hide_password=True)
        except Exception:  # noqa: BLE001 - a URL SQLAlchemy cannot parse is shown as given
            return self.url

    def _fail(self, exc: BaseException, doing: str = "") -> StoreError:
        db = sqlite_file(self.engine)
        if db is not None and not db.exists():  # SQLite says "readonly database" when its file was deleted
            return StoreError(f"results store {self.display_url}{doing}: its file {db} was deleted while open "
                              "(the runs it held are lost with it)")
        return StoreError(f"results store {self.display_url}{doing}: {describe_error(exc)}")

    def _ensure_ready(self) -> None:
        """Migrate once (retried on each write while the store was unreachable)."""
        if self._ready:
            return
        try:
            self.upgrade()
        except DB_ERRORS as exc:
            raise self._fail(exc) from None
        self._ready = True

    def db_now(self) -> str:
        """Wall time for heartbeats, ISO 8601 UTC: the server's clock on PostgreSQL (stations
        sharing one store then judge heartbeats on one clock), this machine's on SQLite."""
        if self.engine.dialect.name != "postgresql":
            return now_iso()
        with self.engine.connect() as conn:
            return conn.execute(text(PG_NOW_ISO)).scalar_one()

    def upgrade(self, revision: str = "head") -> None:
        """Bring the schema to `revision` under the store's migration lock."""
        cfg = _alembic_config()
        with migrating_connection(self.engine) as conn:
            cfg.attributes["connection"] = conn
            command.upgrade(cfg, revision)

    def revision(self) -> str | None:
        with self.engine.connect() as conn:
            return MigrationContext.configure(conn).get_current_revision()

    @staticmethod
    def head() -> str | None:
        return ScriptDirectory.from_config(_alembic_config()).get_current_head()

    def close(self) -> None:
        for beat in self._beats.values():
            beat.stop()
        self._beats.clear()
        self.engine.dispose()

    # --- documents: a run as the store keeps it (and the spool holds it) ------------------------
    @staticmethod
    def record_doc(rec: Any, outcome: str | None = None) -> dict[str, Any]:
        """A run record as plain data: its `run` row, `duts`, `truth` and `measurements` rows."""
        row = {
            "run_id": rec.run_id,
            "procedure": rec.procedure,
            "station_id": rec.station_id,
            "simulated": bool(rec.simulated),
            "outcome": outcome or rec.outcome,
            "end_reason": rec.end_reason if outcome is None else "",
            "safe_state": bool(rec.safe_state) if outcome is None else False,
            "failed_step": rec.failed_step,
            "started_at": rec.started_at,
            "finished_at": rec.finished_at or None,
            "simulated_s": _f(rec.simulated_s),
            "wall_s": _f(rec.wall_s),
            "raw_file": rec.raw_file,
            "software_version": rec.software_version,
            "operator": rec.operator,
            "seed": rec.seed,
            "params": rec.params,
            "safe_detail": rec.safe_detail,
            "host": host_name(),
            "pid": os.getpid(),
            "heartbeat_at": now_iso(),
        }
        return {
            "run": row,
            "duts": list(rec.duts or ()),
            "truth": {k: _f(v) for k, v in (rec.truth or {}).items()},
            "measurements": [] if outcome is not None else _result_rows(rec.measurements, "run"),
        }

    def save_doc(self, doc: dict[str, Any]) -> None:
        """Insert (or replace whole) one run document; raises what the database raises."""
        run_id = doc["run"]["run_id"]
        with self.engine.begin() as conn:
            for table in (measurements, truth, run_duts):
                conn.execute(delete(table).where(table.c.run_id == run_id))
            conn.execute(delete(runs).where(runs.c.run_id == run_id))
            conn.execute(insert(runs), [doc["run"]])
            if doc["duts"]:
                conn.execute(
                    insert(run_duts), [{"run_id": run_id, "slot": i, "serial": s} for i, s in enumerate(doc["duts"])]
                )
            if doc["truth"]:
                conn.execute(
                    insert(truth), [{"run_id": run_id, "name": k, "value": v} for k, v in doc["truth"].items()]
                )
            if doc["measurements"]:
                conn.execute(insert(measurements), [{**m, "run_id": run_id} for m in doc["measurements"]])

    # --- writing -------------------------------------------------------------------------
    def save_run(self, rec: Any) -> None:
        """Insert (or replace) a finished run with its DUTs, measurements and truth."""
        self._stop_heartbeat(rec.run_id)
        self._ensure_ready()
        self.save_doc(self.record_doc(rec))

    def begin_run(self, rec: Any, spool_dir: str | Path | None = None) -> list[str]:
        """Write the run's RUNNING row, keep its heartbeat fresh, and submit what the spool holds.
        Never raises: a store that cannot be written gets the row in the spool.  Notes for the log."""
        spool = Spool(spool_dir) if spool_dir is not None else self.spool
        doc = self.record_doc(rec, outcome=RUNNING)
        try:
            self._ensure_ready()
            doc["run"]["heartbeat_at"] = self.db_now()
            self.save_doc(doc)
        except Exception as exc:  # noqa: BLE001 - whatever the store says, the run goes on and spools
            problem = exc if isinstance(exc, StoreError) else self._fail(exc)
            try:
                path = spool.put(doc)
            except OSError as exc2:
                return [f"{problem}; the spool failed too ({exc2})"]
            return [f"{problem}; the run's record is kept in {path}"]
        run_id = rec.run_id
        self._beats[run_id] = Heartbeat(lambda: self.heartbeat(run_id), self.heartbeat_s, name=f"heartbeat {run_id}")
        submitted, problems = self.sync(spool)
        notes = (
            [f"submitted {len(submitted)} spooled run(s) from {spool.dir}: {', '.join(submitted)}"] if submitted else []
        )
        return notes + problems

    def heartbeat(self, run_id: str) -> None:
        """Refresh a RUNNING row's heartbeat (wall time)."""
        with self.engine.begin() as conn:
            conn.execute(
                update(runs)
                .where((runs.c.run_id == run_id) & (runs.c.outcome == RUNNING))
                .values(heartbeat_at=self.db_now())
            )

    def _stop_heartbeat(self, run_id: str) -> None:
        beat = self._beats.pop(run_id, None)
        if beat is not None:
            beat.stop()

    def finish_run(self, rec: Any, spool_dir: str | Path | None = None) -> str | None:
        """Save a finished run; if the store cannot take it, keep it in the spool.  None when saved,
        else the one-line message for the user (never raises)."""
        spool = Spool(spool_dir) if spool_dir is not None else self.spool
        doc = self.record_doc(rec)
        try:
            self.save_run(rec)
        except Exception as exc:  # noqa: BLE001 - the record must not be lost, whatever the store says
            problem = exc if isinstance(exc, StoreError) else self._fail(exc)
            try:
                path = spool.put(doc)
            except OSError as exc2:
                return f"{problem}; the spool failed too ({exc2}): the run is only in its raw file {rec.raw_file}"
            return f"{problem}; the run's record is kept in {path} (`gyrobench runs --sync` submits it)"
        try:
            spool.remove(rec.run_id)  # the RUNNING row spooled at the start, if the store was down then
        except OSError:
            pass
        return None

    def sync(self, spool: Spool | str | Path | None = None) -> tuple[list[str], list[str]]:
        """Submit the spooled records: (run ids submitted, one-line problems).  A RUNNING record
        whose process still runs here is left for that run; one whose process is gone goes in as
        INTERRUPTED.  Stops at the first record the store refuses (it is down: keep the rest)."""
        spool = spool if isinstance(spool, Spool) else (Spool(spool) if spool is not None else self.spool)
        submitted: list[str] = []
        problems: list[str] = []
        for path in spool.pending():
            try:
                doc = spool.load(path)
                row = doc["run"]
            except (OSError, ValueError, KeyError, TypeError) as exc:
                problems.append(f"spooled record {path} is unreadable ({exc}); left in place")
                continue
            if row["outcome"] == RUNNING:
                if row.get("host") == host_name() and process_alive(row.get("pid")):
                    continue
                row.update(_interrupted(row))
            try:
                self._ensure_ready()
                if row["outcome"] == INTERRUPTED and self._outcome(row["run_id"]) not in (None, RUNNING, INTERRUPTED):
                    pass  # the store already has the run's final record
                else:
                    self.save_doc(doc)
            except STORE_ERRORS as exc:
                problem = exc if isinstance(exc, StoreError) else self._fail(exc)
                problems.append(f"{problem}; {len(spool.pending())} record(s) stay in {spool.dir}")
                break
            path.unlink(missing_ok=True)
            submitted.append(row["run_id"])
        return submitted, problems

    def _outcome(self, run_id: str) -> str | None:
        with self.engine.connect() as conn:
            return conn.execute(select(runs.c.outcome).where(runs.c.run_id == run_id)).scalar()

    def reap(self) -> list[str]:
        """Mark RUNNING rows whose run is gone INTERRUPTED; their ids.  A row whose heartbeat moved
        since it was read is left alone (its run is alive)."""
        cols = (runs.c.run_id, runs.c.host, runs.c.pid, runs.c.heartbeat_at)
        with self.engine.connect() as conn:
            rows = [dict(r._mapping) for r in conn.execute(select(*cols).where(runs.c.outcome == RUNNING))]
        if not rows:
            return []
        now = _dt.datetime.fromisoformat(self.db_now())
        gone = [r for r in rows if is_interrupted(r["host"], r["pid"], r["heartbeat_at"], now=now)]
        done = []
        for r in gone:
            same = (
                runs.c.heartbeat_at.is_(None) if r["heartbeat_at"] is None else runs.c.heartbeat_at == r["heartbeat_at"]
            )
            with self.engine.begin() as conn:
                res = conn.execute(
                    update(runs)
                    .where((runs.c.run_id == r["run_id"]) & (runs.c.outcome == RUNNING) & same)
                    .values(**_interrupted(r))
                )
            if res.rowcount:
                done.append(r["run_id"])
        return done

    def _reap_quietly(self) -> None:
        try:
            self.reap()
        except STORE_ERRORS:  # a read-only store still lists; its RUNNING rows stay as they are
            pass

    def save_analysis(self, run_id: str, results: list[Any]) -> None:
        """Add the measurements of a re-analysis (`gyrobench analyze`), replacing an earlier one."""
        with self.engine.begin() as conn:
            conn.execute(
                delete(measurements).where((measurements.c.run_id == run_id) & (measurements.c.source == "analyze"))
            )
            rows = _result_rows(results, "analyze")
            if rows:
                conn.execute(insert(measurements), [{**m, "run_id": run_id} for m in rows])

    # --- reading -------------------------------------------------------------------------
    def list_runs(self, *, limit: int = 50, procedure: str | None = None, station_id: str | None = None) -> list[dict]:
        """Newest first (RUNNING rows whose run is gone are first marked INTERRUPTED)."""
        self._reap_quietly()
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
            raise KeyError(f"no run {run!r} in {self.display_url}")
        raise KeyError(f"run {run!r} is ambiguous: {ids} ...")

    def get_run(self, run: str) -> dict[str, Any]:
        """The run row with its `duts`, `measurements` (list of dicts) and `truth`."""
        run_id = self.resolve(run)
        self._reap_quietly()
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


def _result_rows(results: list[Any], source: str) -> list[dict[str, Any]]:
    """Measurement rows (without run_id) for a list of Result."""
    rows = []
    now = now_iso()
    for r in results:
        lim = r.limits
        rows.append(
            {
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
    return rows


def _sqlite_pragmas(dbapi_conn, _record) -> None:
    cur = dbapi_conn.cursor()
    cur.execute("PRAGMA foreign_keys=ON")
    cur.execute("PRAGMA busy_timeout=10000")
    cur.close()
