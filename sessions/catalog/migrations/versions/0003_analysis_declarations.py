"""a study's declared analysis, versioned

Revision ID: 0003
Revises: 0002
"""

import sqlalchemy as sa
from alembic import op

revision = "0003"
down_revision = "0002"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "analysis_declarations",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("study_id", sa.Integer(), nullable=False),
        sa.Column("version", sa.Integer(), nullable=False),
        sa.Column("settings", sa.JSON(), nullable=False),
        sa.Column("author", sa.String(length=100), nullable=False),
        sa.Column("note", sa.Text(), nullable=False),
        sa.Column("created_at", sa.DateTime(), nullable=False),
        sa.ForeignKeyConstraint(["study_id"], ["studies.id"], ondelete="CASCADE"),
        sa.PrimaryKeyConstraint("id"),
        sa.UniqueConstraint("study_id", "version", name="uq_analysis_version"),
    )
    with op.batch_alter_table("analysis_declarations", schema=None) as batch_op:
        batch_op.create_index(batch_op.f("ix_analysis_declarations_study_id"), ["study_id"], unique=False)


def downgrade() -> None:
    with op.batch_alter_table("analysis_declarations", schema=None) as batch_op:
        batch_op.drop_index(batch_op.f("ix_analysis_declarations_study_id"))
    op.drop_table("analysis_declarations")
