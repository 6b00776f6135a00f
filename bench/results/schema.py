"""The results store's schema (SQLAlchemy Core): one schema for SQLite and PostgreSQL.

Changes to it go with a new migration in `migrations/versions/`; `tests/test_results.py`
checks that the migrated database matches these tables.
"""

from __future__ import annotations

from sqlalchemy import (
    JSON,
    BigInteger,
    Boolean,
    Column,
    Float,
    ForeignKey,
    Index,
    Integer,
    MetaData,
    String,
    Table,
    Text,
)

from .lengths import OPERATOR_MAX, SERIAL_MAX

metadata = MetaData()

runs = Table(
    "runs",
    metadata,
    Column("run_id", String(64), primary_key=True),
    Column("procedure", String(128), nullable=False),
    Column("station_id", String(128), nullable=False),
    Column("simulated", Boolean, nullable=False, default=False),
    Column("outcome", String(16), nullable=False),
    Column("end_reason", Text, nullable=False, default=""),
    Column("safe_state", Boolean, nullable=False, default=False),
    Column("failed_step", String(128)),
    Column("started_at", String(40), nullable=False),  # ISO 8601 UTC: sorts as text on both engines
    Column("finished_at", String(40)),
    Column("simulated_s", Float),
    Column("wall_s", Float),
    Column("raw_file", Text),
    Column("software_version", String(64), nullable=False, default=""),
    Column("operator", String(OPERATOR_MAX), nullable=False, default=""),
    # a station's seed is 63-bit (migration 0002; SQLite's INTEGER already is, and 0002 leaves it)
    Column("seed", BigInteger().with_variant(Integer(), "sqlite")),
    Column("params", JSON, nullable=False),
    Column("safe_detail", JSON),
    # the run's liveness while RUNNING (migration 0003): where it runs and its heartbeat (wall time)
    Column("host", String(255)),
    Column("pid", Integer),
    Column("heartbeat_at", String(40)),
    Column("run_token", String(128)),  # migration 0004: boot id/pid/start/random (liveness.new_token)
    Index("ix_runs_started_at", "started_at"),
    Index("ix_runs_station_id", "station_id"),
    Index("ix_runs_procedure", "procedure"),
)

run_duts = Table(
    "run_duts",
    metadata,
    Column("run_id", String(64), ForeignKey("runs.run_id", ondelete="CASCADE"), primary_key=True),
    Column("slot", Integer, primary_key=True),
    Column("serial", String(SERIAL_MAX), nullable=False),
    Index("ix_run_duts_serial", "serial"),
)

measurements = Table(
    "measurements",
    metadata,
    Column("id", Integer, primary_key=True, autoincrement=True),
    Column("run_id", String(64), ForeignKey("runs.run_id", ondelete="CASCADE"), nullable=False),
    Column("name", String(128), nullable=False),
    Column("dut", String(128)),
    Column("value", Float),  # NULL for a non-finite value
    Column("unit", String(32), nullable=False, default=""),
    Column("ci95_low", Float),
    Column("ci95_high", Float),
    Column("low", Float),
    Column("high", Float),
    Column("marginal_low", Float),
    Column("marginal_high", Float),
    Column("outcome", String(16), nullable=False),
    Column("source", String(16), nullable=False, default="run"),  # run | analyze
    Column("created_at", String(40), nullable=False),
    Index("ix_measurements_run_id", "run_id"),
    Index("ix_measurements_name", "name"),
)

truth = Table(
    "truth",
    metadata,
    Column("run_id", String(64), ForeignKey("runs.run_id", ondelete="CASCADE"), primary_key=True),
    Column("name", String(128), primary_key=True),
    Column("value", Float),
)
