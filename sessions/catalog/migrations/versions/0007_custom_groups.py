"""a study's declared custom groups; group labels lower-case (a closed, case-insensitive vocabulary)

Revision ID: 0007
Revises: 0006

Existing labels are kept: each is lower-cased, and one outside the standard groups (expert,
intermediate, trainee, novice) becomes a declared custom group of its study, so no participant
changes group or leaves an analysis.
"""

import sqlalchemy as sa
from alembic import op

revision = "0007"
down_revision = "0006"
branch_labels = None
depends_on = None

STANDARD_GROUPS = ("expert", "intermediate", "trainee", "novice")


def upgrade() -> None:
    with op.batch_alter_table("studies", schema=None) as batch_op:
        batch_op.add_column(sa.Column("custom_groups", sa.JSON(), nullable=False, server_default="[]"))
    connection = op.get_bind()
    people = connection.execute(sa.text("SELECT id, study_id, level, group_label FROM participants")).all()
    custom: dict[int, set[str]] = {}
    for person_id, study_id, level, group_label in people:
        level_name = " ".join((level or "").split()).lower()
        group_name = " ".join((group_label or "").split()).lower()
        for name in (level_name, group_name):
            if name and name not in STANDARD_GROUPS:
                custom.setdefault(study_id, set()).add(name)
        connection.execute(
            sa.text("UPDATE participants SET level = :level, group_label = :group WHERE id = :id"),
            {"level": level_name, "group": group_name, "id": person_id},
        )
    studies = sa.table("studies", sa.column("id", sa.Integer), sa.column("custom_groups", sa.JSON))
    for study_id, names in custom.items():
        connection.execute(
            studies.update().where(studies.c.id == study_id).values(custom_groups=sorted(names))
        )


def downgrade() -> None:
    with op.batch_alter_table("studies", schema=None) as batch_op:
        batch_op.drop_column("custom_groups")
