"""where a stored metric value comes from: computed here, or imported from a bundle unverified

Revision ID: 0005
Revises: 0004
"""

import sqlalchemy as sa
from alembic import op

revision = "0005"
down_revision = "0004"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("metric_results", schema=None) as batch_op:
        source = sa.Column("source", sa.String(length=16), nullable=False, server_default="computed")
        batch_op.add_column(source)


def downgrade() -> None:
    with op.batch_alter_table("metric_results", schema=None) as batch_op:
        batch_op.drop_column("source")
