"""per-stitch placement of each scored session

Revision ID: 0006
Revises: 0005
"""

import sqlalchemy as sa
from alembic import op

revision = "0006"
down_revision = "0005"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "stitch_results",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("session_id", sa.Integer(), nullable=False),
        sa.Column("stitch", sa.Integer(), nullable=False),
        sa.Column("quantity", sa.String(length=32), nullable=False),
        sa.Column("value", sa.Float(), nullable=True),
        sa.Column("registry_version", sa.String(length=16), nullable=False),
        sa.ForeignKeyConstraint(["session_id"], ["sessions.id"], ondelete="CASCADE"),
        sa.PrimaryKeyConstraint("id"),
        sa.UniqueConstraint("session_id", "stitch", "quantity", "registry_version", name="uq_stitch_result"),
    )
    with op.batch_alter_table("stitch_results", schema=None) as batch_op:
        batch_op.create_index(batch_op.f("ix_stitch_results_session_id"), ["session_id"], unique=False)


def downgrade() -> None:
    with op.batch_alter_table("stitch_results", schema=None) as batch_op:
        batch_op.drop_index(batch_op.f("ix_stitch_results_session_id"))
    op.drop_table("stitch_results")
