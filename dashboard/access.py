"""Row-level access: what each role may see, applied to every lookup.

- admin, supervisor: everything; researcher: every study, pseudonymously (participant
  codes only, never the linked account or an annotation's author);
- trainee: only the participants linked to their account, their sessions and progress.

An object outside the viewer's reach is answered as not found, so ids cannot be probed.
"""

from __future__ import annotations

from sqlalchemy import select, true
from sqlalchemy.orm import Session as OrmSession

from dashboard.auth import STAFF, Viewer
from dashboard.errors import forbidden, not_found
from sessions.models import Participant, Session, Study


def session_filter(viewer: Viewer):
    """A WHERE clause over Participant limiting rows to what ``viewer`` may see."""
    if viewer.is_trainee:
        return Participant.id.in_(viewer.participant_ids or {-1})
    return true()


def owned_study(orm: OrmSession, viewer: Viewer, study_id: int, whole: bool = False) -> Study:
    """The study, if the viewer may see it; ``whole`` pages (overview, validity) are for staff only."""
    study = orm.get(Study, study_id)
    if study is None:
        raise not_found(f"study {study_id}")
    if viewer.is_trainee:
        mine = orm.scalar(
            select(Participant.id).where(
                Participant.study_id == study_id, Participant.id.in_(viewer.participant_ids or {-1})
            )
        )
        if mine is None:
            raise not_found(f"study {study_id}")
        if whole:
            raise forbidden("a whole study's data")
    elif viewer.role not in STAFF:
        raise forbidden("a study")
    return study


def owned_participant(orm: OrmSession, viewer: Viewer, participant_id: int) -> Participant:
    participant = orm.get(Participant, participant_id)
    if participant is None or (viewer.is_trainee and participant.id not in viewer.participant_ids):
        raise not_found(f"participant {participant_id}")
    return participant


def owned_session(orm: OrmSession, viewer: Viewer, uid: str) -> Session:
    row = orm.scalar(
        select(Session)
        .join(Participant, Session.participant_id == Participant.id)
        .where(Session.uid == uid, session_filter(viewer))
    )
    if row is None:
        raise not_found(f"session {uid!r}")
    return row
