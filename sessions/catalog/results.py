"""The queries of what scoring stored: metric and stitch results by registry version, the study's
declared analyses, which sessions' results are stale or imported, and raters' ratings (the rules are
in :mod:`sessions.scoring`). Each takes the caller's open ORM session first."""

from __future__ import annotations

from collections.abc import Iterable
from datetime import datetime

from sqlalchemy import delete, func, select
from sqlalchemy.orm import Session as OrmSession

from sessions.catalog.models import (
    AnalysisDeclaration,
    MetricResult,
    Participant,
    Rating,
    Session,
    StitchResult,
    Study,
    Task,
)

CHUNK = 500
"""Session ids per IN (...) list (SQLite's and PostgreSQL's parameter limits stay far away)."""


def group_metric_values(
    orm: OrmSession, study_id: int, group: str, task_id: int, statuses: Iterable[str], registry_version: str
) -> list[tuple[str, float]]:
    """(metric, value) of every known value of the study's ``group`` sessions on the task, with one of
    ``statuses``, computed by ``registry_version``."""
    rows = orm.execute(
        select(MetricResult.metric, MetricResult.value)
        .join(Session, MetricResult.session_id == Session.id)
        .join(Participant, Session.participant_id == Participant.id)
        .where(
            Participant.study_id == study_id,
            Participant.group_label == group,
            Session.task_id == task_id,
            Session.status.in_(tuple(statuses)),
            MetricResult.registry_version == registry_version,
            MetricResult.value.is_not(None),
        )
    ).all()
    return [tuple(row) for row in rows]


def stitch_values(
    orm: OrmSession, session_id: int, registry_version: str
) -> list[tuple[int, str, float | None]]:
    """(stitch, quantity, value) of the session's stitches by ``registry_version``, by stitch."""
    rows = orm.execute(
        select(StitchResult.stitch, StitchResult.quantity, StitchResult.value)
        .where(StitchResult.session_id == session_id, StitchResult.registry_version == registry_version)
        .order_by(StitchResult.stitch)
    ).all()
    return [tuple(row) for row in rows]


def task_id_named(orm: OrmSession, name: str) -> int | None:
    """The task's row id, or None when the catalog has no task of that name."""
    return orm.scalar(select(Task.id).where(Task.name == name))


def latest_declaration(orm: OrmSession, study: Study) -> AnalysisDeclaration | None:
    """The study's newest declared analysis, or None before any."""
    return orm.scalar(
        select(AnalysisDeclaration)
        .where(AnalysisDeclaration.study_id == study.id)
        .order_by(AnalysisDeclaration.version.desc())
        .limit(1)
    )


def registry_versions(orm: OrmSession, session_ids: list[int]) -> dict[int, set[str]]:
    """Session id -> the metric registry versions its results were computed by (sessions without
    results left out)."""
    found: dict[int, set[str]] = {}
    for start in range(0, len(session_ids), CHUNK):
        query = (
            select(MetricResult.session_id, MetricResult.registry_version)
            .where(MetricResult.session_id.in_(session_ids[start : start + CHUNK]))
            .distinct()
        )
        for session_id, version in orm.execute(query):
            found.setdefault(session_id, set()).add(version)
    return found


def study_sessions_with(orm: OrmSession, study_id: int, statuses: Iterable[str]) -> list[tuple[int, str]]:
    """(session id, uid) of the study's sessions with one of ``statuses``."""
    rows = orm.execute(
        select(Session.id, Session.uid)
        .join(Participant, Session.participant_id == Participant.id)
        .where(Participant.study_id == study_id, Session.status.in_(tuple(statuses)))
    ).all()
    return [tuple(row) for row in rows]


def imported_result_sessions(orm: OrmSession, study_id: int, registry_version: str) -> list[str]:
    """uids of the study's sessions with results of ``registry_version`` imported, not computed here."""
    return list(
        orm.scalars(
            select(Session.uid)
            .join(Participant, Session.participant_id == Participant.id)
            .join(MetricResult, MetricResult.session_id == Session.id)
            .where(
                Participant.study_id == study_id,
                MetricResult.source == "imported",
                MetricResult.registry_version == registry_version,
            )
            .distinct()
            .order_by(Session.uid)
        )
    )


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
