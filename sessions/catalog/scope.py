"""Who is reading, and the row-level rule every scoped lookup applies.

- admin, supervisor: everything; researcher: every study, pseudonymously (participant codes only,
  never the linked account or an annotation's author);
- trainee: only the participants linked to their account, their sessions and progress.

Something outside the reader's reach is answered exactly as something that does not exist
(:class:`sessions.catalog.NotFound`, "... not found"), so ids cannot be probed.
"""

from __future__ import annotations

from dataclasses import dataclass

from sqlalchemy import select, true
from sqlalchemy.orm import Session as OrmSession

from sessions.catalog.errors import Forbidden, NotFound
from sessions.catalog.models import Participant, Session, Study

STAFF = ("admin", "supervisor", "researcher")
"""Roles that see whole studies (researchers pseudonymously)."""


@dataclass(frozen=True)
class Scope:
    """A reader: their role and, for a trainee, the participants linked to their account."""

    role: str
    participant_ids: frozenset[int] = frozenset()

    @property
    def is_trainee(self) -> bool:
        return self.role == "trainee"

    @property
    def sees_accounts(self) -> bool:
        """Admins and supervisors see which account a participant belongs to; researchers never do."""
        return self.role in ("admin", "supervisor")

    @property
    def is_staff(self) -> bool:
        return self.role in STAFF


EVERYTHING = Scope("admin")
"""The scope of a command run on the catalog's own machine (the CLI)."""


def hidden(what: str) -> NotFound:
    """The same answer for "does not exist" and "not yours"."""
    return NotFound(what, "", message=f"{what} not found")


def needs_role(what: str) -> Forbidden:
    return Forbidden(f"{what} needs a different role")


def visible(scope: Scope):
    """A WHERE clause over Participant limiting rows to what ``scope`` may see."""
    if scope.is_trainee:
        return Participant.id.in_(scope.participant_ids or {-1})
    return true()


def owned_study(orm: OrmSession, scope: Scope, study_id: int, whole: bool = False) -> Study:
    """The study, if the reader may see it; ``whole`` (overview, validity, rating) is for staff only."""
    study = orm.get(Study, study_id)
    if study is None:
        raise hidden(f"study {study_id}")
    if scope.is_trainee:
        mine = orm.scalar(select(Participant.id).where(Participant.study_id == study_id, visible(scope)))
        if mine is None:
            raise hidden(f"study {study_id}")
        if whole:
            raise needs_role("a whole study's data")
    elif not scope.is_staff:
        raise needs_role("a study")
    return study


def owned_participant(orm: OrmSession, scope: Scope, participant_id: int) -> Participant:
    participant = orm.get(Participant, participant_id)
    if participant is None or (scope.is_trainee and participant.id not in scope.participant_ids):
        raise hidden(f"participant {participant_id}")
    return participant


def owned_session(orm: OrmSession, scope: Scope, uid: str) -> Session:
    row = orm.scalar(
        select(Session)
        .join(Participant, Session.participant_id == Participant.id)
        .where(Session.uid == uid, visible(scope))
    )
    if row is None:
        raise hidden(f"session {uid!r}")
    return row
