"""The results store: runs, DUTs, measurements and truth, through SQLAlchemy Core.

`ResultsStore(url)` takes a SQLAlchemy URL (`sqlite:///runs/results.sqlite`, the default, or
`postgresql+psycopg://user@host/db` on a production line) or a plain file path, and brings
the schema to the newest migration on open (under a lock: see `locks.py`).

A run's row is written when it starts (`begin_run`: outcome RUNNING, a run token and a heartbeat
on the store's clock kept fresh by a daemon thread) and replaced when it ends (`finish_run`).  A
RUNNING row whose run is gone (`liveness.is_interrupted`) becomes INTERRUPTED when the store is
listed; a live run's next heartbeat restores it.  A record the store cannot take is kept in a
spool (`spool.py`) and submitted by `sync`; one it refuses is quarantined with its reason.

On PostgreSQL every write of a run waits a bounded time (`wait_s`): connect and statement
timeouts, a pre-ping of pooled connections, one retry of a lost connection, and a bound of the
caller's own (`deadline.py`) for a server that accepts and never answers; a user waiting is told
so after `SLOW_NOTICE_S`.  Then the record goes to the spool.
"""

from __future__ import annotations

import datetime as _dt
import math
import os
import re
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

from sqlalchemy import create_engine, delete, event, insert, literal_column, select, text, update
from sqlalchemy.engine import Connection, Engine, make_url
from sqlalchemy.exc import (
    DataError,
    DBAPIError,
    IntegrityError,
    InterfaceError,
    OperationalError,
    SQLAlchemyError,
    StatementError,
)

from bench.engine.measurement import INTERRUPTED, RUNNING

from .deadline import NoAnswer, call_bounded
from .fresh import build_fresh, is_fresh
from .limits import RecordRefused, check_doc
from .liveness import (
    HEARTBEAT_S,
    Heartbeat,
    host_name,
    is_interrupted,
    new_token,
    now_iso,
    process_alive,
    token_alive_here,
)
from .locks import migrating_connection, sqlite_file
from .redact import redact_text
from .schema import measurements, run_duts, runs, truth
from .spool import Spool

if TYPE_CHECKING:
    from alembic.config import Config

T = TypeVar("T")

DEFAULT_PATH = Path("runs") / "results.sqlite"
MIGRATIONS = Path(__file__).resolve().parent / "migrations"
POSTGRES_EXTRA = "pip install 'gyrobench[postgres]'"
PG_NOW_SQL = """to_char(clock_timestamp() AT TIME ZONE 'UTC', 'YYYY-MM-DD"T"HH24:MI:SS.US"+00:00"')"""
PG_NOW_ISO = f"SELECT {PG_NOW_SQL}"
# pg_advisory_xact_lock(RUN_LOCK_SPACE, hashtext(run_id)): one writer of a run's rows at a time
RUN_LOCK_SPACE = 0x67796231

CONNECT_TIMEOUT_S = 5  # a server that accepts and never answers the start-up: given up after this
WAIT_S = 10.0  # the longest one write of a run waits for the store (both tries), then it spools
DOWN_WAIT_S = 3.0  # once the store has not answered in this process: one short try, then the spool
SLOW_NOTICE_S = 2.0  # a user waiting this long on the store is told why (at most half the wait)
WAIT_ENV = "GYROBENCH_STORE_WAIT_S"  # overrides WAIT_S (e.g. a short bound for a test of the outage rules)
RETRY_PAUSE_S = 0.5  # before the one retry of a lost connection (a server restarting)


class StoreError(Exception):
    """The results store cannot be opened, reached or written; the message is one line for a user."""


def default_wait_s() -> float:
    """The bound of one write: $GYROBENCH_STORE_WAIT_S if set (a positive number of seconds), else WAIT_S."""
    text = os.environ.get(WAIT_ENV, "").strip()
    if not text:
        return WAIT_S
    try:
        value = float(text)
    except ValueError:
        raise StoreError(f"{WAIT_ENV}={text!r} is not a number of seconds") from None
    if not 1.0 <= value <= 3600.0:
        raise StoreError(f"{WAIT_ENV}={text!r} is not between 1 and 3600 s")
    return value


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
    """The first line of what the database said (no SQL, no traceback, no password)."""
    inner = getattr(exc, "orig", None) or exc
    lines = [ln.strip() for ln in str(inner).splitlines() if ln.strip()]
    return redact_text(lines[0]) if lines else type(inner).__name__


def is_refusal(exc: BaseException) -> bool:
    """The store refuses this record (and always will): not a store that is down."""
    if isinstance(exc, RecordRefused | DataError | IntegrityError):
        return True
    return isinstance(exc, StatementError) and not isinstance(exc, DBAPIError)  # a value it cannot bind


def _is_lost_connection(exc: BaseException) -> bool:
    """A connection that failed or was lost (worth one retry), not a refusal."""
    if isinstance(exc, DBAPIError) and exc.connection_invalidated:
        return True
    return isinstance(exc, OperationalError | InterfaceError)


def _postgres_connect_args(url: str, connect_timeout_s: float, statement_timeout_s: float) -> dict[str, Any]:
    """psycopg's connect_timeout and the server's statement_timeout, unless the URL sets them."""
    query = make_url(url).query
    args: dict[str, Any] = {}
    if "connect_timeout" not in query:
        args["connect_timeout"] = max(2, int(math.ceil(connect_timeout_s)))  # libpq's least is 2 s
    options = query.get("options", "")
    options = " ".join(options) if isinstance(options, tuple) else options
    if "statement_timeout" not in options:
        args["options"] = f"{options} -c statement_timeout={int(statement_timeout_s * 1000)}".strip()
    return args


def _f(x: Any) -> float | None:
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


def _alembic_config() -> Config:
    from alembic.config import Config  # alembic (~0.3 s of imports) only when a schema is migrated

    cfg = Config()
    cfg.set_main_option("script_location", str(MIGRATIONS))
    return cfg


def _import_alembic() -> None:
    """alembic's modules, imported before a store call that may migrate: their ~0.3 s (seconds on a
    loaded machine) must not count as the store's wait (a bounded call, a 'no answer' notice)."""
    import alembic.command  # noqa: F401
    import alembic.config  # noqa: F401
    import alembic.runtime.migration  # noqa: F401
    import alembic.script  # noqa: F401


def head_revision(versions: Path = MIGRATIONS / "versions") -> str | None:
    """The newest migration's revision, read from the migration files' `revision` and
    `down_revision` lines without importing alembic (tests check it against alembic's head)."""
    revisions, parents = set(), set()
    for path in versions.glob("*.py"):
        source = path.read_text(encoding="utf-8")
        rev = re.search(r'^revision\s*=\s*["\']([^"\']+)["\']', source, re.M)
        if rev is None:
            continue
        revisions.add(rev.group(1))
        down = re.search(r'^down_revision\s*=\s*["\']([^"\']+)["\']', source, re.M)
        if down is not None:
            parents.add(down.group(1))
    heads = revisions - parents
    return heads.pop() if len(heads) == 1 else None


def _interrupted(row: dict[str, Any]) -> dict[str, Any]:
    """The fields that turn a RUNNING row whose run is gone into INTERRUPTED (raw file kept)."""
    beat = (row.get("heartbeat_at") or "")[:19] or "never"
    return {
        "outcome": INTERRUPTED,
        "end_reason": f"interrupted: no sign of the run (host {row.get('host')}, process "
        f"{row.get('pid')}, last heartbeat {beat})",
        "finished_at": row.get("heartbeat_at"),
        "safe_state": False,
    }


def _stderr(message: str) -> None:
    print(f"gyrobench: {message}", file=sys.stderr, flush=True)


class ResultsStore:
    """Indexes runs and their measurements; the same code for SQLite and PostgreSQL.

    `offline_ok=True` lets a store that cannot be reached now be opened anyway (writes then fail,
    and `begin_run` / `finish_run` spool); otherwise opening raises StoreError.  `wait_s` bounds
    each write's wait on PostgreSQL; `notify` gets the one line telling a waiting user why (stderr
    by default)."""

    def __init__(
        self,
        url: str | Path | None = None,
        *,
        upgrade: bool = True,
        offline_ok: bool = False,
        spool_dir: str | Path | None = None,
        wait_s: float | None = None,
        connect_timeout_s: float = CONNECT_TIMEOUT_S,
        notify: Callable[[str], None] | None = _stderr,
    ) -> None:
        self.url = to_url(url)
        self.wait_s = wait_s = default_wait_s() if wait_s is None else wait_s
        self.notify = notify
        self._down = False  # the store did not answer in this process (cleared by an answer)
        self._told = False  # the waiting user was told (once while the store stays down)
        kw: dict[str, Any] = {}
        if self.url.startswith("postgres"):
            kw = {
                "pool_pre_ping": True,  # a pooled connection the server dropped (a restart) is replaced
                "pool_timeout": wait_s,
                "connect_args": _postgres_connect_args(self.url, connect_timeout_s, wait_s),
            }
        try:
            self.engine: Engine = create_engine(self.url, **kw)
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
        self._tokens: dict[str, str] = {}
        self.heartbeat_s = HEARTBEAT_S
        self._ready = not upgrade
        self._fresh = False  # the first look found no tables: built at once (fresh.py), no alembic
        self.open_error: str | None = None
        if upgrade:
            try:
                then = "then the run goes on and its record goes to the spool" if offline_ok else "then it gives up"
                self._ready = self._call(self._first_look, then, opening=True)  # no alembic needed
                self._call(self._ensure_ready, then)  # a migration: alembic imported first, outside the wait
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
        except Exception:  # noqa: BLE001 - a URL SQLAlchemy cannot parse is shown as given, redacted
            return redact_text(self.url)

    @property
    def host(self) -> str:
        """Where the store is, for a waiting user: the server's host, or the SQLite file."""
        try:
            u = make_url(self.url)
        except Exception:  # noqa: BLE001
            return self.display_url
        if self.engine.dialect.name == "sqlite":
            return str(u.database)
        if u.host:
            return u.host
        service = u.query.get("service")
        return f"service {service}" if service else os.environ.get("PGHOST", "local socket")

    def _fail(self, exc: BaseException, doing: str = "") -> StoreError:
        db = sqlite_file(self.engine)
        if db is not None and not db.exists():  # SQLite says "readonly database" when its file was deleted
            return StoreError(f"results store {self.display_url}{doing}: its file {db} was deleted while open "
                              "(the runs it held are lost with it)")
        return StoreError(f"results store {self.display_url}{doing}: {describe_error(exc)}")

    def _call(self, fn: Callable[[], T], then: str = "then the record goes to the spool", *,
              retry: bool = True, tell: bool = True, opening: bool = False) -> T:
        """fn() against the store within the wait: one retry of a lost connection, StoreError
        naming the store when it did not answer or failed (what fn raised when it refused).
        While the schema is not known to be at the head (fn may migrate it), alembic is imported
        first, outside the wait; `opening`: fn is the first look, which needs no alembic."""
        if not self._ready and not opening and not self._fresh:  # a fresh store is built without alembic
            _import_alembic()
        local = self.engine.dialect.name != "postgresql"  # a local file: SQLite's busy_timeout bounds the wait
        budget = min(DOWN_WAIT_S, self.wait_s) if self._down else self.wait_s
        notice_s = min(SLOW_NOTICE_S, self.wait_s / 2.0)
        t0 = time.monotonic()

        def tries() -> T:
            try:
                return fn()
            except DBAPIError as exc:
                if not retry or not _is_lost_connection(exc) or budget - (time.monotonic() - t0) < 2 * RETRY_PAUSE_S:
                    raise
            time.sleep(RETRY_PAUSE_S)
            return fn()

        def slow(elapsed_s: float) -> None:
            if self.notify is None or self._told:
                return
            self._told = True
            tail = f", {then}" if then else ""
            # whole seconds gone by, rounded down: "1 s" stays true of a notice a loaded machine wakes late
            self.notify(f"results store at {self.host}: no answer for {math.floor(elapsed_s)} s, waiting up to "
                        f"{budget:.0f} s{tail}")

        try:
            if local:
                out = fn()
            else:
                out = call_bounded(tries, budget, slow_after_s=notice_s if tell else None, on_slow=slow)
        except NoAnswer as exc:
            self._down = True
            raise StoreError(f"results store {self.display_url}: {exc}") from None
        except RecordRefused:
            raise
        except DB_ERRORS as exc:
            if is_refusal(exc):
                raise
            if _is_lost_connection(exc):
                self._down = True
            raise self._fail(exc) from None
        self._down = self._told = False
        return out

    def _ensure_ready(self) -> None:
        """Migrate once (retried on each write while the store was unreachable)."""
        if self._ready:
            return
        try:
            self.upgrade()
        except DB_ERRORS as exc:
            if _is_lost_connection(exc):
                raise
            raise self._fail(exc) from None
        self._ready = True

    def _now_sql(self) -> Any:
        """The store's clock as a value to write: the server's on PostgreSQL."""
        return literal_column(PG_NOW_SQL) if self.engine.dialect.name == "postgresql" else now_iso()

    def db_now(self) -> str:
        """Wall time for heartbeats, ISO 8601 UTC: the server's clock on PostgreSQL (stations
        sharing one store then judge heartbeats on one clock), this machine's on SQLite."""
        if self.engine.dialect.name != "postgresql":
            return now_iso()
        with self.engine.connect() as conn:
            return conn.execute(text(PG_NOW_ISO)).scalar_one()

    def upgrade(self, revision: str = "head") -> None:
        """Bring the schema to `revision` under the store's migration lock; a store already at the
        head is seen by one query, without alembic (every command that opens the store paid ~0.3 s
        of alembic's imports and its migration scripts' loading for nothing: issue 36)."""
        if revision == "head" and self._at_head():
            return
        head = head_revision()
        if revision == "head" and head is not None:
            with migrating_connection(self.engine) as conn:  # the lock: one process builds, the others see it
                if is_fresh(conn):
                    build_fresh(conn, head)  # the newest schema at once (fresh.py; the same as migrated)
                    return
            if self._at_head():  # another process built it while this one waited for the lock
                return
        from alembic import command

        cfg = _alembic_config()
        with migrating_connection(self.engine) as conn:
            cfg.attributes["connection"] = conn
            command.upgrade(cfg, revision)

    def _first_look(self) -> bool:
        """Whether the schema is at the head; notes a store with no tables yet (built without alembic)."""
        if self._at_head():
            return True
        with self.engine.connect() as conn:
            self._fresh = is_fresh(conn)
        return False

    def _at_head(self) -> bool:
        """Whether the store's schema is at the newest migration (alembic's version table)."""
        head = head_revision()
        if head is None:
            return False
        with self.engine.connect() as conn:
            if not self.engine.dialect.has_table(conn, "alembic_version"):
                return False
            return conn.execute(text("SELECT version_num FROM alembic_version")).scalars().all() == [head]

    def revision(self) -> str | None:
        from alembic.runtime.migration import MigrationContext

        with self.engine.connect() as conn:
            return MigrationContext.configure(conn).get_current_revision()

    @staticmethod
    def head() -> str | None:
        from alembic.script import ScriptDirectory

        return ScriptDirectory.from_config(_alembic_config()).get_current_head()

    def close(self) -> None:
        for beat in self._beats.values():
            beat.stop()
        self._beats.clear()
        self.engine.dispose()

    # --- documents: a run as the store keeps it (and the spool holds it) ------------------------
    @staticmethod
    def record_doc(rec: Any, outcome: str | None = None, token: str | None = None) -> dict[str, Any]:
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
            "run_token": token or new_token(),
        }
        return {
            "run": row,
            "duts": list(rec.duts or ()),
            "truth": {k: _f(v) for k, v in (rec.truth or {}).items()},
            "measurements": [] if outcome is not None else _result_rows(rec.measurements, "run"),
        }

    def _lock_run(self, conn: Connection, run_id: str) -> None:
        """Hold the run's lock for the transaction: writers of one run (syncs at once) take turns."""
        if self.engine.dialect.name == "postgresql":
            conn.execute(text("SELECT pg_advisory_xact_lock(:space, hashtext(:run_id))"),
                         {"space": RUN_LOCK_SPACE, "run_id": run_id})

    def _replace(self, conn: Connection, doc: dict[str, Any]) -> None:
        run_id = doc["run"]["run_id"]
        for table in (measurements, truth, run_duts):
            conn.execute(delete(table).where(table.c.run_id == run_id))
        conn.execute(delete(runs).where(runs.c.run_id == run_id))
        conn.execute(insert(runs), [doc["run"]])
        if doc["duts"]:
            conn.execute(
                insert(run_duts), [{"run_id": run_id, "slot": i, "serial": s} for i, s in enumerate(doc["duts"])]
            )
        if doc["truth"]:
            conn.execute(insert(truth), [{"run_id": run_id, "name": k, "value": v} for k, v in doc["truth"].items()])
        if doc["measurements"]:
            conn.execute(insert(measurements), [{**m, "run_id": run_id} for m in doc["measurements"]])

    def save_doc(self, doc: dict[str, Any], *, server_clock: bool = False) -> None:
        """Insert (or replace whole) one run document, under the run's lock; raises what the
        database raises (RecordRefused before sending a text longer than its column)."""
        check_doc(doc)
        with self.engine.begin() as conn:
            self._lock_run(conn, doc["run"]["run_id"])
            if doc["run"]["outcome"] == RUNNING:  # a start that reached the store late never hides the end
                have = conn.execute(select(runs.c.outcome).where(runs.c.run_id == doc["run"]["run_id"])).scalar()
                if have not in (None, RUNNING, INTERRUPTED):
                    return
            if server_clock and self.engine.dialect.name == "postgresql":
                doc["run"]["heartbeat_at"] = conn.execute(text(PG_NOW_ISO)).scalar_one()
            self._replace(conn, doc)

    def _submit(self, doc: dict[str, Any]) -> bool:
        """Save a spooled document unless the store already holds the run's final record (an
        INTERRUPTED one stands back); whether it was written."""
        row = doc["run"]
        check_doc(doc)
        self._ensure_ready()
        with self.engine.begin() as conn:
            self._lock_run(conn, row["run_id"])
            if row["outcome"] == INTERRUPTED:
                have = conn.execute(select(runs.c.outcome).where(runs.c.run_id == row["run_id"])).scalar()
                if have not in (None, RUNNING, INTERRUPTED):
                    return False
            self._replace(conn, doc)
        return True

    # --- writing -------------------------------------------------------------------------
    def save_run(self, rec: Any) -> None:
        """Insert (or replace) a finished run with its DUTs, measurements and truth (within the wait)."""
        self._stop_heartbeat(rec.run_id)
        doc = self.record_doc(rec, token=self._tokens.get(rec.run_id))

        def write() -> None:
            self._ensure_ready()
            self.save_doc(doc)

        self._call(write)

    def begin_run(self, rec: Any, spool_dir: str | Path | None = None) -> list[str]:
        """Write the run's RUNNING row, keep its heartbeat fresh, and submit what the spool holds.
        Never raises: a store that cannot be written gets the row in the spool.  Notes for the log."""
        spool = Spool(spool_dir) if spool_dir is not None else self.spool
        token = self._tokens.setdefault(rec.run_id, new_token())
        doc = self.record_doc(rec, outcome=RUNNING, token=token)

        def write() -> None:
            self._ensure_ready()
            self.save_doc(doc, server_clock=True)

        try:
            self._call(write, "then the run goes on and its record goes to the spool")
        except RecordRefused as exc:  # the final record will be refused too: finish_run quarantines it
            return [f"results store {self.display_url} refuses the run's record: {exc}"]
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

    def heartbeat(self, run_id: str) -> bool:
        """Refresh the run's heartbeat on the store's clock; a row taken for gone while the store
        was out of reach (INTERRUPTED by another station) is RUNNING again.  Only this run's token
        matches.  Whether a row was touched."""
        token = self._tokens.get(run_id)
        with self.engine.begin() as conn:
            res = conn.execute(
                update(runs)
                .where((runs.c.run_id == run_id) & (runs.c.run_token == token)
                       & runs.c.outcome.in_((RUNNING, INTERRUPTED)))
                .values(heartbeat_at=self._now_sql(), outcome=RUNNING, end_reason="", finished_at=None,
                        safe_state=False)
            )
        return bool(res.rowcount)

    def _stop_heartbeat(self, run_id: str) -> None:
        beat = self._beats.pop(run_id, None)
        if beat is not None:
            beat.stop()

    def finish_run(self, rec: Any, spool_dir: str | Path | None = None) -> str | None:
        """Save a finished run; if the store cannot take it, keep it in the spool (a record it
        refuses: in the spool's quarantine with the reason).  None when saved, else the one-line
        message for the user (never raises)."""
        spool = Spool(spool_dir) if spool_dir is not None else self.spool
        doc = self.record_doc(rec, token=self._tokens.get(rec.run_id))
        try:
            self.save_run(rec)
        except Exception as exc:  # noqa: BLE001 - the record must not be lost, whatever the store says
            refused = is_refusal(exc)
            problem = self._fail(exc, " refuses the run's record") if refused else (
                exc if isinstance(exc, StoreError) else self._fail(exc))
            try:
                path = spool.put(doc)
                if refused:
                    path = spool.quarantine(path, str(problem))
            except OSError as exc2:
                return f"{problem}; the spool failed too ({exc2}): the run is only in its raw file {rec.raw_file}"
            if refused:
                return f"{problem}; the run's record is kept in {path} with its reason"
            return f"{problem}; the run's record is kept in {path} (`gyrobench runs --sync` submits it)"
        finally:
            self._tokens.pop(rec.run_id, None)
        try:
            spool.remove(rec.run_id)  # the RUNNING row spooled at the start, if the store was down then
        except OSError:
            pass
        return None

    def sync(self, spool: Spool | str | Path | None = None) -> tuple[list[str], list[str]]:
        """Submit the spooled records: (run ids submitted, one-line problems).  A RUNNING record
        whose process still runs here is left for that run; one whose process is gone goes in as
        INTERRUPTED.  A record the store refuses goes to the spool's quarantine (with a `.reason`)
        and the rest go on; at a store that is down, the rest stay.  Syncs at once submit each
        record once (a lock per record file, and per run in the store)."""
        spool = spool if isinstance(spool, Spool) else (Spool(spool) if spool is not None else self.spool)
        submitted: list[str] = []
        problems: list[str] = []
        for path in spool.pending():
            with spool.claim(path) as mine:
                if not mine:
                    continue  # another sync submits it (or did)
                try:
                    doc = spool.load(path)
                    row = doc["run"]
                except (OSError, ValueError, KeyError, TypeError) as exc:
                    problems.append(f"spooled record {path} is unreadable ({exc}); left in place")
                    continue
                if row["outcome"] == RUNNING:
                    alive = token_alive_here(row.get("run_token"))
                    if alive is None and not row.get("run_token"):  # a record spooled before run tokens
                        alive = row.get("host") == host_name() and process_alive(row.get("pid"))
                    if alive:
                        continue
                    row.update(_interrupted(row))
                try:
                    self._call(lambda doc=doc: self._submit(doc), "then the records stay in the spool")
                except Exception as exc:  # noqa: BLE001 - refused: quarantined; else the store is down
                    if not is_refusal(exc):
                        problem = exc if isinstance(exc, StoreError) else self._fail(exc)
                        problems.append(f"{problem}; {len(spool.pending())} record(s) stay in {spool.dir}")
                        break
                    reason = str(exc) if isinstance(exc, RecordRefused) else describe_error(exc)
                    try:
                        dest = spool.quarantine(path, reason)
                    except OSError as exc2:
                        problems.append(f"spooled record {path} is refused ({reason}) and cannot be moved ({exc2})")
                        continue
                    problems.append(f"spooled record {row['run_id']} is refused by the store ({reason}): moved to "
                                    f"{dest} with its .reason; the other records go on")
                    continue
                path.unlink(missing_ok=True)
                submitted.append(row["run_id"])
        return submitted, problems

    def _outcome(self, run_id: str) -> str | None:
        with self.engine.connect() as conn:
            return conn.execute(select(runs.c.outcome).where(runs.c.run_id == run_id)).scalar()

    def reap(self) -> list[str]:
        """Mark RUNNING rows whose run is gone INTERRUPTED; their ids.  A row whose heartbeat moved
        since it was read is left alone (its run is alive)."""
        cols = (runs.c.run_id, runs.c.host, runs.c.pid, runs.c.heartbeat_at, runs.c.run_token)
        with self.engine.connect() as conn:
            rows = [dict(r._mapping) for r in conn.execute(select(*cols).where(runs.c.outcome == RUNNING))]
        if not rows:
            return []
        now = _dt.datetime.fromisoformat(self.db_now())
        gone = [r for r in rows if is_interrupted(r["run_token"], r["heartbeat_at"], now=now)]
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
            self._call(self.reap, tell=False)
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
