"""The queries of raters' ratings (the rules, instruments and checks are in
:mod:`sessions.scoring.ratings`). Each takes the caller's open ORM session first."""

from __future__ import annotations

from datetime import datetime

from sqlalchemy import delete, func, select
from sqlalchemy.orm import Session as OrmSession

from sessions.catalog.models import Participant, Rating, Session


def _by(session_id: int, rater: str, instrument: str):
    return (Rating.session_id == session_id) & (Rating.rater == rater) & (Rating.instrument == instrument)


def has_rated(orm: OrmSession, session_id: int, rater: str, instrument: str) -> bool:
    """Whether ``rater`` already rated the session with the instrument."""
    return orm.scalar(select(Rating.id).where(_by(session_id, rater, instrument)).limit(1)) is not None


def forget_rating(orm: OrmSession, session_id: int, rater: str, instrument: str) -> None:
    """Drop ``rater``'s rating of the session with the instrument (before it is replaced)."""
    orm.execute(delete(Rating).where(_by(session_id, rater, instrument)))


def study_rating_rows(
    orm: OrmSession, study_id: int, instrument: str | None = None
) -> list[tuple[str, str, str, str, str, str, float, datetime]]:
    """(session uid, participant code, group, rater, instrument, item, score, created at) of every
    rating of the study's sessions (with ``instrument`` when given), in time order."""
    query = (
        select(
            Session.uid,
            Participant.code,
            Participant.group_label,
            Rating.rater,
            Rating.instrument,
            Rating.item,
            Rating.score,
            Rating.created_at,
        )
        .join(Session, Rating.session_id == Session.id)
        .join(Participant, Session.participant_id == Participant.id)
        .where(Participant.study_id == study_id)
        .order_by(Rating.created_at, Rating.id)
    )
    if instrument is not None:
        query = query.where(Rating.instrument == instrument)
    return [tuple(row) for row in orm.execute(query).all()]


def raters_in_order(orm: OrmSession) -> list[str]:
    """Every rater in the catalog, in the order of their first rating."""
    rows = orm.execute(
        select(Rating.rater, func.min(Rating.id)).group_by(Rating.rater).order_by(func.min(Rating.id))
    ).all()
    return [rater for rater, _ in rows]


def session_rating_rows(orm: OrmSession, session_id: int) -> list[tuple[str, str, str, float, datetime]]:
    """(rater, instrument, item, score, created at) of the session's ratings, in time order."""
    rows = orm.execute(
        select(Rating.rater, Rating.instrument, Rating.item, Rating.score, Rating.created_at)
        .where(Rating.session_id == session_id)
        .order_by(Rating.created_at, Rating.id)
    ).all()
    return [tuple(row) for row in rows]
