"""The line database: one row per unit, per attempt (with its whole JSON record) and per judged
measurement; SQLite by default, PostgreSQL for a line of several stations (the same URL as the
results store: `line_*` tables under their own migration chain).

Several stations write at once: each record is one transaction; a SQLite writer that finds the
file locked, or two stations that drew the same attempt number, retry (bounded), so nothing is lost.
"""

from __future__ import annotations

import os
import random
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sqlalchemy import event, func, insert, select, text, update
from sqlalchemy.exc import IntegrityError, OperationalError, SQLAlchemyError

from bench.results.liveness import STALE_S, age_s, host_name, process_alive
from bench.results.liveness import now_iso as _now
from bench.results.locks import migrating_connection
from bench.results.redact import redact_text
from bench.results.store import describe_error, head_revision, to_url

from . import LineError
from .schema import VERSION_TABLE, line_attempts, line_measurements, line_units

if TYPE_CHECKING:
    from alembic.config import Config
    from sqlalchemy.engine import Connection

RUNNING, INTERRUPTED = "RUNNING", "INTERRUPTED"  # an attempt row before its record / whose process died
OPEN = (RUNNING, INTERRUPTED)
MIGRATIONS = Path(__file__).resolve().parent / "migrations"
RETRY_S = 30.0  # how long a record waits for a busy database before the error is reported


def _alembic_config() -> Config:
    from alembic.config import Config  # alembic (~0.3 s of CPU in imports) only when a migration is due

    cfg = Config()
    cfg.set_main_option("script_location", str(MIGRATIONS))
    return cfg


def _at_head(conn: Connection) -> bool:
    """Whether the line's version table holds the newest migration's revision, read from the files."""
    head = head_revision(MIGRATIONS / "versions")
    if head is None or not conn.dialect.has_table(conn, VERSION_TABLE):
        return False
    return conn.execute(text(f"SELECT version_num FROM {VERSION_TABLE}")).scalars().all() == [head]


def _sqlite_pragmas(dbapi_conn, _record) -> None:
    cur = dbapi_conn.cursor()
    cur.execute("PRAGMA foreign_keys=ON")
    cur.execute("PRAGMA busy_timeout=10000")
    cur.close()


def _num(x: Any) -> float | None:
    return None if x is None else float(x)


class LineDB:
    """Records of units on one database URL (or SQLite file path)."""

    def __init__(self, url: str | Path | None = None) -> None:
        from sqlalchemy import create_engine

        self.url = to_url(url)
        #: the URL as messages show it: a password in it is masked (bench.results.redact)
        self.shown_url = redact_text(self.url)
        try:
            self.engine = create_engine(self.url)
        except ImportError as exc:
            raise LineError(f"line database {self.shown_url}: its driver is not installed ({exc})") from None
        if self.engine.dialect.name == "sqlite":
            event.listen(self.engine, "connect", _sqlite_pragmas)
        try:
            self.upgrade()
        except SQLAlchemyError as exc:
            raise LineError(f"line database {self.shown_url}: cannot be opened: {describe_error(exc)}") from None

    def upgrade(self) -> None:
        """Bring the line's tables to the newest migration under the migration lock; a database already
        there is seen by one query, without alembic (each line station process paid ~0.3 s of CPU for
        alembic's imports and its migration scripts: issue 36)."""
        with migrating_connection(self.engine) as conn:
            if _at_head(conn):
                return
            from alembic import command

            cfg = _alembic_config()
            cfg.attributes["connection"] = conn
            command.upgrade(cfg, "head")

    def close(self) -> None:
        self.engine.dispose()

    # --- writing -----------------------------------------------------------------------------
    def next_attempt(self, serial: str) -> int:
        """One more than the highest attempt of the serial in the database (RUNNING rows count)."""
        with self.engine.connect() as conn:
            n = conn.execute(select(func.max(line_attempts.c.attempt)).where(line_attempts.c.serial == serial)).scalar()
        return int(n or 0) + 1

    def save(self, record: dict[str, Any]) -> int:
        """Insert one record (its unit, attempt and measurements) in one transaction; its attempt id.
        An attempt number another station took meanwhile becomes the next free one."""
        deadline = time.monotonic() + RETRY_S
        while True:
            try:
                return self._insert(record)
            except IntegrityError:
                if record.get("integrity"):  # a sealed record is never renumbered (its hash covers it)
                    raise LineError(f"line database {self.shown_url}: attempt {record['attempt']} of "
                                    f"{record['serial']} is already there (the JSON record is kept: "
                                    f"{record.get('record_file')})"
                                    ) from None
                record["attempt"] = self.next_attempt(record["serial"])
            except OperationalError as exc:  # SQLite: the file is locked by another writer
                if time.monotonic() > deadline:
                    raise LineError(f"line database {self.shown_url}: record of {record['serial']} not saved: "
                                    f"{describe_error(exc)} (the JSON record is kept: {record.get('record_file')})"
                                    ) from None
            time.sleep(random.uniform(0.01, 0.1))

    def has(self, record: dict[str, Any]) -> bool:
        """Whether this record (its serial and start time) is already stored whole (an attempt row
        still RUNNING or INTERRUPTED waits for its record: not stored)."""
        row = self.find(record)
        return row is not None and row["outcome"] not in OPEN

    def find(self, record: dict[str, Any]) -> dict[str, Any] | None:
        """The attempt row (id, attempt, outcome) of this record's serial and start time, or None."""
        q = select(line_attempts.c.id, line_attempts.c.attempt, line_attempts.c.outcome).where(
            line_attempts.c.serial == record["serial"], line_attempts.c.started_at == record["started_at"])
        with self.engine.connect() as conn:
            row = conn.execute(q).first()
        return None if row is None else dict(row._mapping)

    def has_attempt(self, serial: str, attempt: int) -> bool:
        q = select(line_attempts.c.id).where(line_attempts.c.serial == serial, line_attempts.c.attempt == attempt)
        with self.engine.connect() as conn:
            return conn.execute(q).first() is not None

    # --- attempts as they run ----------------------------------------------------------------
    def begin_attempt(self, stub: dict[str, Any]) -> int:
        """The attempt's row when it starts: RUNNING, with this host, process and a heartbeat, so a
        process killed mid-unit leaves a row that becomes INTERRUPTED; its id.  An attempt number
        another station took meanwhile becomes the next free one (stub["attempt"] is updated)."""
        deadline = time.monotonic() + RETRY_S
        while True:
            try:
                with self.engine.begin() as conn:
                    self._ensure_unit(conn, stub)
                    row = self._attempt_row(stub)
                    row.update(outcome=RUNNING, host=host_name(), pid=os.getpid(), heartbeat_at=_now(),
                               ended_at=stub["started_at"])
                    return int(conn.execute(insert(line_attempts).returning(line_attempts.c.id), [row]).scalar_one())
            except IntegrityError:
                stub["attempt"] = self.next_attempt(stub["serial"])
            except OperationalError as exc:
                if time.monotonic() > deadline or self.engine.dialect.name != "sqlite":
                    raise LineError(f"line database {self.shown_url}: attempt of {stub['serial']} not begun: "
                                    f"{describe_error(exc)}") from None
            time.sleep(random.uniform(0.01, 0.1))

    def beat(self, attempt_id: int) -> None:
        """A RUNNING attempt is alive (its heartbeat, every few seconds)."""
        with self.engine.begin() as conn:
            conn.execute(update(line_attempts).where(line_attempts.c.id == attempt_id,
                                                     line_attempts.c.outcome == RUNNING)
                         .values(heartbeat_at=_now()))

    def finish_attempt(self, attempt_id: int, record: dict[str, Any]) -> None:
        """The attempt's row gets its record (outcome, measurements), in one transaction."""
        try:
            with self.engine.begin() as conn:
                row = self._attempt_row(record)
                row.update(host=None, pid=None, heartbeat_at=None)
                conn.execute(update(line_attempts).where(line_attempts.c.id == attempt_id).values(**row))
                self._insert_measurements(conn, attempt_id, record)
        except SQLAlchemyError as exc:
            raise LineError(f"line database {self.shown_url}: record of {record['serial']} not saved: "
                            f"{describe_error(exc)} (the JSON record is kept: {record.get('record_file')})") from None

    def reap(self) -> int:
        """RUNNING attempts whose process is gone (its host's process, or a stale heartbeat) become
        INTERRUPTED, as runs do in the results store; how many."""
        c = line_attempts.c
        with self.engine.begin() as conn:
            rows = conn.execute(select(c.id, c.host, c.pid, c.heartbeat_at, c.record).where(c.outcome == RUNNING)).all()
            n = 0
            for r in rows:
                if not _attempt_gone(r.host, r.pid, r.heartbeat_at):
                    continue
                stub = dict(r.record or {})
                stub.update(outcome=INTERRUPTED, end_reason=f"interrupted: the attempt ended without a record "
                            f"(host {r.host}, process {r.pid}, last heartbeat {(r.heartbeat_at or 'never')[:19]})")
                ended = r.heartbeat_at or stub.get("started_at")
                conn.execute(update(line_attempts).where(c.id == r.id, c.outcome == RUNNING)
                             .values(outcome=INTERRUPTED, record=stub, ended_at=ended))
                n += 1
        return n

    def save_many(self, records: list[dict[str, Any]]) -> None:
        """Insert many records in one transaction (an import, a benchmark's fill): all or none."""
        with self.engine.begin() as conn:
            for rec in records:
                self._insert(rec, conn)

    def _insert(self, rec: dict[str, Any], conn: Any = None) -> int:
        if conn is None:
            with self.engine.begin() as conn:
                return self._insert(rec, conn)
        self._ensure_unit(conn, rec)
        attempt_id = conn.execute(insert(line_attempts).returning(line_attempts.c.id),
                                  [self._attempt_row(rec)]).scalar_one()
        self._insert_measurements(conn, attempt_id, rec)
        return int(attempt_id)

    @staticmethod
    def _ensure_unit(conn: Any, rec: dict[str, Any]) -> None:
        exists = conn.execute(select(line_units.c.serial).where(line_units.c.serial == rec["serial"])).first()
        if exists is None:
            conn.execute(insert(line_units), [{"serial": rec["serial"], "lot": rec.get("lot", ""),
                                               "first_seen_at": rec["started_at"]}])

    @staticmethod
    def _attempt_row(rec: dict[str, Any]) -> dict[str, Any]:
        row = {k: rec.get(k, "") for k in ("serial", "attempt", "lot", "station", "operator", "sequence",
                                           "software_version", "started_at", "ended_at", "outcome")}
        row["ended_at"] = row["ended_at"] or rec["started_at"]
        row["product"] = rec.get("product", "")
        row["record"] = rec
        row["chain_index"] = (rec.get("chain") or {}).get("index")
        return row

    @staticmethod
    def _insert_measurements(conn: Any, attempt_id: int, rec: dict[str, Any]) -> None:
        rows = []
        for m in rec["measurements"]:
            iv = m.get("interval") or [None, None]
            lim = m.get("limits") or {}
            rows.append({"attempt_id": attempt_id, "serial": rec["serial"], "name": m["name"],
                         "procedure": m.get("procedure") or "", "run_id": m.get("run_id"),
                         "value": _num(m.get("value")), "unit": m.get("unit") or "",
                         "interval_low": _num(iv[0]), "interval_high": _num(iv[1]),
                         "low": _num(lim.get("low")), "high": _num(lim.get("high")), "rule": m.get("rule"),
                         "outcome": m["outcome"], "ended_at": rec["ended_at"]})
        if rows:
            conn.execute(insert(line_measurements), rows)

    # --- reading -----------------------------------------------------------------------------
    def attempts(self, *, lot: str | None = None, serial: str | None = None) -> list[dict[str, Any]]:
        """Attempts (without their JSON records), oldest first; RUNNING and INTERRUPTED ones too."""
        self.reap()
        cols = [c for c in line_attempts.c if c.name != "record"]
        q = select(*cols).order_by(line_attempts.c.ended_at, line_attempts.c.id)
        if lot is not None:
            q = q.where(line_attempts.c.lot == lot)
        if serial is not None:
            q = q.where(line_attempts.c.serial == serial)
        with self.engine.connect() as conn:
            return [dict(r._mapping) for r in conn.execute(q)]

    def records(self, *, lot: str | None = None, station: str | None = None, serial: str | None = None,
                open_too: bool = False) -> list[dict[str, Any]]:
        """Whole records, oldest first (with open_too, the stubs of RUNNING / INTERRUPTED attempts)."""
        self.reap()
        q = select(line_attempts.c.record).order_by(line_attempts.c.ended_at, line_attempts.c.id)
        if lot is not None:
            q = q.where(line_attempts.c.lot == lot)
        if station is not None:
            q = q.where(line_attempts.c.station == station)
        if serial is not None:
            q = q.where(line_attempts.c.serial == serial)
        if not open_too:
            q = q.where(line_attempts.c.outcome.not_in(OPEN))
        with self.engine.connect() as conn:
            return [r[0] for r in conn.execute(q)]

    def chain_head(self, station: str) -> tuple[int, str | None]:
        """The station's last chained record in the database: (its index, its hash), (0, None) if none."""
        c = line_attempts.c
        q = select(c.chain_index, c.record).where(c.station == station, c.chain_index.is_not(None)).order_by(
            c.chain_index.desc()).limit(1)
        with self.engine.connect() as conn:
            row = conn.execute(q).first()
        if row is None:
            return 0, None
        return int(row.chain_index), (row.record.get("integrity") or {}).get("sha256")

    def records_at(self, station: str, index: int) -> list[dict[str, Any]]:
        """The records a station's chain holds at one index (normally one)."""
        q = select(line_attempts.c.record).where(line_attempts.c.station == station,
                                                 line_attempts.c.chain_index == index)
        with self.engine.connect() as conn:
            return [r[0] for r in conn.execute(q)]

    def measurements(self, *, lot: str | None = None) -> list[dict[str, Any]]:
        """Judged measurements with limits (their attempt's lot, station and time), oldest first."""
        m, a = line_measurements, line_attempts
        q = (select(m.c.name, m.c.procedure, m.c.serial, m.c.value, m.c.unit, m.c.low, m.c.high, m.c.rule,
                    m.c.outcome, m.c.ended_at, a.c.lot, a.c.station, a.c.attempt, a.c.product, a.c.sequence)
             .join(a, a.c.id == m.c.attempt_id).where(m.c.rule.is_not(None))
             .order_by(m.c.ended_at, m.c.id))
        if lot is not None:
            q = q.where(a.c.lot == lot)
        with self.engine.connect() as conn:
            return [dict(r._mapping) for r in conn.execute(q)]

    def count(self) -> tuple[int, int]:
        """(attempts, measurements) stored."""
        with self.engine.connect() as conn:
            return (conn.execute(select(func.count()).select_from(line_attempts)).scalar_one(),
                    conn.execute(select(func.count()).select_from(line_measurements)).scalar_one())


def _attempt_gone(host: str | None, pid: int | None, heartbeat_at: str | None) -> bool:
    """A RUNNING attempt is over: its heartbeat is stale, or it ran on this host and its process is
    gone (an attempt row names its host and process; a fresh heartbeat from elsewhere is a live unit)."""
    if age_s(heartbeat_at) > STALE_S:
        return True
    return host == host_name() and not process_alive(pid)
