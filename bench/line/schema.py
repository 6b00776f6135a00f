"""The line database's tables (SQLAlchemy Core): units, their attempts (each with its whole JSON
record) and the judged measurements, for the line report's queries.

They live in the results store's database (same URL) under their own migration chain and version
table, so the line's schema changes never interleave with the run store's chain."""

from __future__ import annotations

from sqlalchemy import JSON, Column, Float, ForeignKey, Index, Integer, MetaData, String, Table, UniqueConstraint

VERSION_TABLE = "line_alembic_version"
metadata = MetaData()

line_units = Table(
    "line_units",
    metadata,
    Column("serial", String(128), primary_key=True),
    Column("lot", String(128), nullable=False, default=""),
    Column("first_seen_at", String(40), nullable=False),
)

line_attempts = Table(
    "line_attempts",
    metadata,
    Column("id", Integer, primary_key=True, autoincrement=True),
    Column("serial", String(128), ForeignKey("line_units.serial"), nullable=False),
    Column("attempt", Integer, nullable=False),
    Column("lot", String(128), nullable=False, default=""),
    Column("station", String(128), nullable=False),
    Column("operator", String(128), nullable=False, default=""),
    Column("sequence", String(128), nullable=False),
    Column("product", String(128), nullable=False, default=""),
    Column("software_version", String(64), nullable=False, default=""),
    Column("started_at", String(40), nullable=False),  # ISO 8601 UTC: sorts as text on both engines
    Column("ended_at", String(40), nullable=False),
    Column("outcome", String(16), nullable=False),
    Column("record", JSON, nullable=False),  # the whole record; a stub while RUNNING / INTERRUPTED
    Column("host", String(255)),  # where a RUNNING attempt runs (with pid and heartbeat: is it alive?)
    Column("pid", Integer),
    Column("heartbeat_at", String(40)),
    Column("chain_index", Integer),  # its place in its station's record chain (bench/line/integrity.py)
    UniqueConstraint("serial", "attempt", name="uq_line_attempts_serial_attempt"),
    Index("ix_line_attempts_lot", "lot"),
    Index("ix_line_attempts_ended_at", "ended_at"),
    Index("ix_line_attempts_station", "station"),
    Index("ix_line_attempts_serial", "serial"),
)

line_measurements = Table(
    "line_measurements",
    metadata,
    Column("id", Integer, primary_key=True, autoincrement=True),
    Column("attempt_id", Integer, ForeignKey("line_attempts.id", ondelete="CASCADE"), nullable=False),
    Column("serial", String(128), nullable=False),
    Column("name", String(128), nullable=False),
    Column("procedure", String(128), nullable=False, default=""),
    Column("run_id", String(64)),
    Column("value", Float),
    Column("unit", String(32), nullable=False, default=""),
    Column("interval_low", Float),
    Column("interval_high", Float),
    Column("low", Float),
    Column("high", Float),
    Column("rule", String(16)),
    Column("outcome", String(16), nullable=False),
    Column("ended_at", String(40), nullable=False),
    Index("ix_line_measurements_attempt", "attempt_id"),
    Index("ix_line_measurements_name", "name"),
)
