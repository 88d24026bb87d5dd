"""Rows found inside a caller's transaction: the queries of the flows that hold one open while they
work on what they find (recording, replaying, recovering, the demo's reset), written here so that
no module outside the catalog writes SQL. Each takes the open ORM session first."""

from __future__ import annotations

from collections.abc import Iterable

from sqlalchemy import delete, func, insert, select
from sqlalchemy.orm import Session as OrmSession

from sessions.catalog.models import Participant, Session, StreamFile, Study, Task


def session_with_uid(orm: OrmSession, uid: str) -> Session | None:
    """The session with this uid, or None."""
    return orm.scalar(select(Session).where(Session.uid == uid))


def session_in_directory(orm: OrmSession, directories: Iterable[str]) -> Session | None:
    """The session recorded in one of ``directories`` (the path as given and as resolved), or None."""
    return orm.scalar(select(Session).where(Session.directory.in_(tuple(directories))))


def latest_session_of(
    orm: OrmSession, study_id: int, code: str, task_id: int, statuses: Iterable[str]
) -> Session | None:
    """Participant ``code``'s latest session on the task, in the study, with one of ``statuses``."""
    return orm.scalar(
        select(Session)
        .join(Participant, Session.participant_id == Participant.id)
        .where(
            Participant.study_id == study_id,
            Participant.code == code,
            Session.task_id == task_id,
            Session.status.in_(tuple(statuses)),
        )
        .order_by(Session.started_at.desc(), Session.id.desc())
        .limit(1)
    )


def group_sessions(
    orm: OrmSession,
    study_id: int,
    labels: Iterable[str],
    task_id: int,
    statuses: Iterable[str],
    other_than: str,
) -> list[Session]:
    """The study's sessions on the task by participants of the group ``labels``, with one of
    ``statuses``, session ``other_than`` aside, in the order they were catalogued."""
    return list(
        orm.scalars(
            select(Session)
            .join(Participant, Session.participant_id == Participant.id)
            .where(
                Participant.study_id == study_id,
                Participant.group_label.in_(tuple(labels)),
                Session.status.in_(tuple(statuses)),
                Session.uid != other_than,
                Session.task_id == task_id,
            )
            .order_by(Session.id)
        ).all()
    )


def forget_stream_files(orm: OrmSession, session_id: int) -> None:
    """Drop the session's file rows (before the files are listed again with their checksums)."""
    orm.execute(delete(StreamFile).where(StreamFile.session_id == session_id))


def forget_results(orm: OrmSession, tables: Iterable[type], session_id: int, registry_version: str) -> None:
    """Drop the session's rows of ``tables`` (metric and stitch results) computed by this registry
    version (before they are stored again)."""
    for table in tables:
        orm.execute(
            delete(table).where(table.session_id == session_id, table.registry_version == registry_version)
        )


def study_named(orm: OrmSession, name: str) -> Study | None:
    """The study of that name, or None."""
    return orm.scalar(select(Study).where(Study.name == name))


def study_session_keys(orm: OrmSession, study_name: str) -> list[tuple[str, str, str, int, str]]:
    """(uid, participant code, task name, trial, phase) of every session of the study."""
    rows = orm.execute(
        select(Session.uid, Participant.code, Task.name, Session.trial, Session.phase)
        .join(Participant, Session.participant_id == Participant.id)
        .join(Study, Participant.study_id == Study.id)
        .join(Task, Session.task_id == Task.id)
        .where(Study.name == study_name)
    ).all()
    return [tuple(row) for row in rows]


def participants_of(orm: OrmSession, study_id: int) -> list[Participant]:
    """The study's participants by code."""
    return list(
        orm.scalars(select(Participant).where(Participant.study_id == study_id).order_by(Participant.code))
    )


def participant_coded(orm: OrmSession, study_id: int, code: str) -> Participant | None:
    """The study's participant with this code, or None."""
    return orm.scalar(select(Participant).where(Participant.study_id == study_id, Participant.code == code))


def first_catalogued(orm: OrmSession, uids: Iterable[str]) -> str | None:
    """One of the session ids ``uids`` the catalog already holds, or None."""
    return orm.scalar(select(Session.uid).where(Session.uid.in_(list(uids))).limit(1))


def participant_activity(orm: OrmSession, study_id: int) -> list[tuple[str, str, int, object, object]]:
    """(code, group, sessions, first and latest session start (None without any)) of each of the
    study's participants, by code."""
    rows = orm.execute(
        select(
            Participant.code,
            Participant.group_label,
            func.count(Session.id),
            func.min(Session.started_at),
            func.max(Session.started_at),
        )
        .outerjoin(Session, Session.participant_id == Participant.id)
        .where(Participant.study_id == study_id)
        .group_by(Participant.id)
        .order_by(Participant.code)
    ).all()
    return [tuple(row) for row in rows]


def insert_rows(orm: OrmSession, table: type, rows: list[dict]) -> None:
    """Bulk insert plain rows into ``table`` (one statement; a synthetic study's thousands of sessions)."""
    orm.execute(insert(table), rows)
