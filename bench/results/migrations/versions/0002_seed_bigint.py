"""runs.seed as BIGINT: a station accepts 63-bit seeds (SQLite's INTEGER already holds them).

Revision ID: 0002
Revises: 0001
"""

import sqlalchemy as sa
from alembic import op

revision = "0002"
down_revision = "0001"
branch_labels = None
depends_on = None


def upgrade() -> None:
    if op.get_bind().dialect.name == "sqlite":
        return  # SQLite's INTEGER is 64-bit; recreating the table would gain nothing
    with op.batch_alter_table("runs") as batch:
        batch.alter_column("seed", type_=sa.BigInteger, existing_type=sa.Integer, existing_nullable=True)


def downgrade() -> None:
    if op.get_bind().dialect.name == "sqlite":
        return
    with op.batch_alter_table("runs") as batch:
        batch.alter_column("seed", type_=sa.Integer, existing_type=sa.BigInteger, existing_nullable=True)
