"""Attempt rows written when an attempt starts (RUNNING), with the host, process and heartbeat that
tell a live attempt from one whose process died (INTERRUPTED), and the station's chain index.

Revision ID: line0002
Revises: line0001
"""

import sqlalchemy as sa
from alembic import op

revision = "line0002"
down_revision = "line0001"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("line_attempts") as batch:
        batch.add_column(sa.Column("host", sa.String(255)))
        batch.add_column(sa.Column("pid", sa.Integer))
        batch.add_column(sa.Column("heartbeat_at", sa.String(40)))
        batch.add_column(sa.Column("chain_index", sa.Integer))
    op.create_index("ix_line_attempts_station", "line_attempts", ["station"])
    op.create_index("ix_line_attempts_serial", "line_attempts", ["serial"])


def downgrade() -> None:
    op.drop_index("ix_line_attempts_serial", "line_attempts")
    op.drop_index("ix_line_attempts_station", "line_attempts")
    with op.batch_alter_table("line_attempts") as batch:
        batch.drop_column("chain_index")
        batch.drop_column("heartbeat_at")
        batch.drop_column("pid")
        batch.drop_column("host")
