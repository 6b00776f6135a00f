"""The line database: units, attempts (with their JSON records) and judged measurements.

Revision ID: line0001
Revises:
"""

import sqlalchemy as sa
from alembic import op

revision = "line0001"
down_revision = None
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "line_units",
        sa.Column("serial", sa.String(128), primary_key=True),
        sa.Column("lot", sa.String(128), nullable=False),
        sa.Column("first_seen_at", sa.String(40), nullable=False),
    )
    op.create_table(
        "line_attempts",
        sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
        sa.Column("serial", sa.String(128), sa.ForeignKey("line_units.serial"), nullable=False),
        sa.Column("attempt", sa.Integer, nullable=False),
        sa.Column("lot", sa.String(128), nullable=False),
        sa.Column("station", sa.String(128), nullable=False),
        sa.Column("operator", sa.String(128), nullable=False),
        sa.Column("sequence", sa.String(128), nullable=False),
        sa.Column("product", sa.String(128), nullable=False),
        sa.Column("software_version", sa.String(64), nullable=False),
        sa.Column("started_at", sa.String(40), nullable=False),
        sa.Column("ended_at", sa.String(40), nullable=False),
        sa.Column("outcome", sa.String(16), nullable=False),
        sa.Column("record", sa.JSON, nullable=False),
        sa.UniqueConstraint("serial", "attempt", name="uq_line_attempts_serial_attempt"),
    )
    op.create_index("ix_line_attempts_lot", "line_attempts", ["lot"])
    op.create_index("ix_line_attempts_ended_at", "line_attempts", ["ended_at"])
    op.create_table(
        "line_measurements",
        sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
        sa.Column("attempt_id", sa.Integer, sa.ForeignKey("line_attempts.id", ondelete="CASCADE"), nullable=False),
        sa.Column("serial", sa.String(128), nullable=False),
        sa.Column("name", sa.String(128), nullable=False),
        sa.Column("procedure", sa.String(128), nullable=False),
        sa.Column("run_id", sa.String(64)),
        sa.Column("value", sa.Float),
        sa.Column("unit", sa.String(32), nullable=False),
        sa.Column("interval_low", sa.Float),
        sa.Column("interval_high", sa.Float),
        sa.Column("low", sa.Float),
        sa.Column("high", sa.Float),
        sa.Column("rule", sa.String(16)),
        sa.Column("outcome", sa.String(16), nullable=False),
        sa.Column("ended_at", sa.String(40), nullable=False),
    )
    op.create_index("ix_line_measurements_attempt", "line_measurements", ["attempt_id"])
    op.create_index("ix_line_measurements_name", "line_measurements", ["name"])


def downgrade() -> None:
    op.drop_table("line_measurements")
    op.drop_table("line_attempts")
    op.drop_table("line_units")
