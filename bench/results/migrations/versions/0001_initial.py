"""Initial schema: runs, run_duts, measurements, truth.

Revision ID: 0001
Revises:
"""

import sqlalchemy as sa
from alembic import op

revision = "0001"
down_revision = None
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "runs",
        sa.Column("run_id", sa.String(64), primary_key=True),
        sa.Column("procedure", sa.String(128), nullable=False),
        sa.Column("station_id", sa.String(128), nullable=False),
        sa.Column("simulated", sa.Boolean, nullable=False),
        sa.Column("outcome", sa.String(16), nullable=False),
        sa.Column("end_reason", sa.Text, nullable=False),
        sa.Column("safe_state", sa.Boolean, nullable=False),
        sa.Column("failed_step", sa.String(128)),
        sa.Column("started_at", sa.String(40), nullable=False),
        sa.Column("finished_at", sa.String(40)),
        sa.Column("simulated_s", sa.Float),
        sa.Column("wall_s", sa.Float),
        sa.Column("raw_file", sa.Text),
        sa.Column("software_version", sa.String(64), nullable=False),
        sa.Column("operator", sa.String(128), nullable=False),
        sa.Column("seed", sa.Integer),
        sa.Column("params", sa.JSON, nullable=False),
        sa.Column("safe_detail", sa.JSON),
    )
    op.create_index("ix_runs_started_at", "runs", ["started_at"])
    op.create_index("ix_runs_station_id", "runs", ["station_id"])
    op.create_index("ix_runs_procedure", "runs", ["procedure"])
    op.create_table(
        "run_duts",
        sa.Column("run_id", sa.String(64), sa.ForeignKey("runs.run_id", ondelete="CASCADE"), primary_key=True),
        sa.Column("slot", sa.Integer, primary_key=True),
        sa.Column("serial", sa.String(128), nullable=False),
    )
    op.create_index("ix_run_duts_serial", "run_duts", ["serial"])
    op.create_table(
        "measurements",
        sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
        sa.Column("run_id", sa.String(64), sa.ForeignKey("runs.run_id", ondelete="CASCADE"), nullable=False),
        sa.Column("name", sa.String(128), nullable=False),
        sa.Column("dut", sa.String(128)),
        sa.Column("value", sa.Float),
        sa.Column("unit", sa.String(32), nullable=False),
        sa.Column("ci95_low", sa.Float),
        sa.Column("ci95_high", sa.Float),
        sa.Column("low", sa.Float),
        sa.Column("high", sa.Float),
        sa.Column("marginal_low", sa.Float),
        sa.Column("marginal_high", sa.Float),
        sa.Column("outcome", sa.String(16), nullable=False),
        sa.Column("source", sa.String(16), nullable=False),
        sa.Column("created_at", sa.String(40), nullable=False),
    )
    op.create_index("ix_measurements_run_id", "measurements", ["run_id"])
    op.create_index("ix_measurements_name", "measurements", ["name"])
    op.create_table(
        "truth",
        sa.Column("run_id", sa.String(64), sa.ForeignKey("runs.run_id", ondelete="CASCADE"), primary_key=True),
        sa.Column("name", sa.String(128), primary_key=True),
        sa.Column("value", sa.Float),
    )


def downgrade() -> None:
    op.drop_table("truth")
    op.drop_table("measurements")
    op.drop_table("run_duts")
    op.drop_table("runs")
