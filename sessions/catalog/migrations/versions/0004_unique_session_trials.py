"""one session per (participant, task, trial): concurrent runs can no longer share a trial number

Sessions that already share one (left by runs before this constraint) are renumbered in the
order they started, keeping the trial order the analyses read.

Revision ID: 0004
Revises: 0003
"""

import sqlalchemy as sa
from alembic import op

revision = "0004"
down_revision = "0003"
branch_labels = None
depends_on = None


def _renumber_duplicates() -> None:
    connection = op.get_bind()
    clashes = connection.execute(
        sa.text(
            "SELECT participant_id, task_id FROM sessions GROUP BY participant_id, task_id, trial "
            "HAVING COUNT(*) > 1"
        )
    ).fetchall()
    for participant_id, task_id in sorted(set(clashes)):
        rows = connection.execute(
            sa.text(
                "SELECT id FROM sessions WHERE participant_id = :p AND task_id = :t "
                "ORDER BY trial, started_at, id"
            ),
            {"p": participant_id, "t": task_id},
        ).fetchall()
        for trial, (session_id,) in enumerate(rows, start=1):
            update = sa.text("UPDATE sessions SET trial = :trial WHERE id = :id")
            connection.execute(update, {"trial": -trial, "id": session_id})
        connection.execute(
            sa.text("UPDATE sessions SET trial = -trial WHERE participant_id = :p AND task_id = :t"),
            {"p": participant_id, "t": task_id},
        )


def upgrade() -> None:
    _renumber_duplicates()
    with op.batch_alter_table("sessions", schema=None) as batch_op:
        batch_op.create_unique_constraint("uq_session_trial", ["participant_id", "task_id", "trial"])


def downgrade() -> None:
    with op.batch_alter_table("sessions", schema=None) as batch_op:
        batch_op.drop_constraint("uq_session_trial", type_="unique")
