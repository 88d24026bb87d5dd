"""The queries of a study's standards: their versions, the verdicts kept under them and the log of
re-judgings (the rules are in :mod:`sessions.scoring.standards` and :mod:`sessions.scoring.verdicts`).
Each takes the caller's open ORM session first."""

from __future__ import annotations

from collections.abc import Iterable
from datetime import datetime

from sqlalchemy import select
from sqlalchemy.orm import Session as OrmSession

from sessions.catalog.models import Rejudgement, Session, Standard, Verdict


def standards_of(orm: OrmSession, study_id: int, task: str | None = None) -> list[Standard]:
    """Every version of the study's standards (on ``task`` when given), by task, oldest first."""
    query = select(Standard).where(Standard.study_id == study_id)
    if task is not None:
        query = query.where(Standard.task == task)
    return list(orm.scalars(query.order_by(Standard.task, Standard.version)).all())


def latest_version(orm: OrmSession, study_id: int, task: str) -> int:
    """The newest version number of the study's standard on ``task`` (0 when none was set)."""
    latest = orm.scalar(
        select(Standard.version)
        .where(Standard.study_id == study_id, Standard.task == task)
        .order_by(Standard.version.desc())
        .limit(1)
    )
    return latest or 0


def standard_ids(orm: OrmSession, study_id: int, task: str) -> dict[int, int]:
    """Version -> the standard's row id, for the study's standard on ``task``."""
    rows = orm.execute(
        select(Standard.version, Standard.id).where(Standard.study_id == study_id, Standard.task == task)
    ).all()
    return dict(rows)


def kept_verdict_rows(
    orm: OrmSession, uids: Iterable[str]
) -> list[tuple[str, int, datetime | None, bool | None, int | None]]:
    """(uid, session id, started at, passed, standard version) of each session named, the last two
    None for a session never judged."""
    rows = orm.execute(
        select(Session.uid, Session.id, Session.started_at, Verdict.passed, Standard.version)
        .outerjoin(Verdict, Verdict.session_id == Session.id)
        .outerjoin(Standard, Standard.id == Verdict.standard_id)
        .where(Session.uid.in_(list(uids)))
    ).all()
    return [tuple(row) for row in rows]


def session_ids(orm: OrmSession, uids: Iterable[str]) -> dict[str, int]:
    """uid -> the session's row id, for the sessions named that the catalog holds."""
    return dict(orm.execute(select(Session.uid, Session.id).where(Session.uid.in_(list(uids)))).all())


def verdicts_of(orm: OrmSession, session_ids: Iterable[int]) -> dict[int, Verdict]:
    """Session row id -> its kept verdict, for those of ``session_ids`` judged."""
    found = orm.scalars(select(Verdict).where(Verdict.session_id.in_(list(session_ids))))
    return {verdict.session_id: verdict for verdict in found}


def study_verdicts(orm: OrmSession, study_id: int) -> list[tuple[Verdict, int]]:
    """(verdict, the version of the standard that gave it) of every session of the study judged."""
    found = orm.execute(
        select(Verdict, Standard.version)
        .join(Standard, Verdict.standard_id == Standard.id)
        .where(Standard.study_id == study_id)
    ).all()
    return [tuple(row) for row in found]


def rejudgements_of(orm: OrmSession, standard_ids: Iterable[int]) -> list[Rejudgement]:
    """The re-judging log entries under the standards named, oldest first."""
    found = orm.scalars(
        select(Rejudgement).where(Rejudgement.standard_id.in_(list(standard_ids))).order_by(Rejudgement.id)
    )
    return list(found)


def rejudgement_log(orm: OrmSession, study_id: int, task: str) -> list[tuple[int, Rejudgement]]:
    """(standard version, log entry) of every re-judging of the study's standard on ``task``, oldest
    first."""
    rows = orm.execute(
        select(Standard.version, Rejudgement)
        .join(Standard, Standard.id == Rejudgement.standard_id)
        .where(Standard.study_id == study_id, Standard.task == task)
        .order_by(Rejudgement.id)
    ).all()
    return [tuple(row) for row in rows]
