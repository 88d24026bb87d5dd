"""The catalog store's listings: studies, participants and sessions as every front-end lists them,
which sessions are scorable, the study table an analysis reads, and deleting a session's rows.
Scoped lookups take the reader's :class:`sessions.catalog.scope.Scope` (the CLI reads everything)."""

from __future__ import annotations

import pandas as pd
from sqlalchemy import case, func, or_, select
from sqlalchemy.orm import Session as OrmSession

from metrics.session.registry import REGISTRY, REGISTRY_VERSION
from sessions.catalog.engine import Catalog
from sessions.catalog.errors import WrongState
from sessions.catalog.models import MetricResult, Participant, Rating, Session, Study, Task, User
from sessions.catalog.records import ParticipantRecord, SessionRecord, StudyRecord, StudySummary
from sessions.catalog.scope import EVERYTHING, Scope, visible
from sessions.status import SCORABLE, SCRIPTED_DEVICE


def sessions_with(*columns):
    """A query of ``columns`` over sessions joined to their participant and task."""
    return (
        select(*columns)
        .join(Participant, Session.participant_id == Participant.id)
        .join(Task, Session.task_id == Task.id)
    )


LISTED = (
    Session.id,
    Session.uid,
    Study.name,
    Participant.code,
    Task.name,
    Session.trial,
    Session.phase,
    Session.device,
    Session.status,
    Session.started_at,
    Session.ended_at,
)
"""The columns of a :class:`SessionRecord`, in its order."""


def synthetic_session():
    """A session is synthetic when its participant is, or when a script, not a hand, moved the needle
    (a scripted run for a real participant code is still not evidence about that person)."""
    return or_(Participant.synthetic, Session.device == SCRIPTED_DEVICE)


def listed_sessions():
    """A query of :data:`LISTED` (add WHERE and ORDER BY)."""
    return sessions_with(*LISTED).join(Study, Participant.study_id == Study.id)


class Listings:
    catalog: Catalog

    def studies(self, scope: Scope = EVERYTHING) -> list[StudySummary]:
        """Studies by name with their participant and session counts (a trainee's: only those where
        they are a participant, counting only their own)."""
        query = (
            select(
                Study.id,
                Study.name,
                Study.description,
                func.count(func.distinct(Participant.id)),
                func.count(Session.id),
                func.max(case((synthetic_session(), 1), else_=0)),
            )
            .outerjoin(Participant, Participant.study_id == Study.id)
            .outerjoin(Session, Session.participant_id == Participant.id)
            .group_by(Study.id)
            .order_by(Study.name)
        )
        if scope.is_trainee:
            query = query.where(visible(scope))
        with self.catalog.session() as orm:
            rows = orm.execute(query).all()
        return [StudySummary(i, n, d, p, s, bool(y)) for i, n, d, p, s, y in rows]

    def study_named(self, name: str) -> StudyRecord:
        """A study by name (unknown: NotFound naming the nearest)."""
        with self.catalog.session() as orm:
            found = self.catalog.study(orm, name)
            return StudyRecord(found.id, found.name, found.description)

    def studies_of_sessions(self, uids: list[str]) -> list[str]:
        """The names of the studies these sessions belong to, sorted."""
        with self.catalog.session() as orm:
            return sorted(
                orm.scalars(
                    select(Study.name)
                    .join(Participant, Participant.study_id == Study.id)
                    .join(Session, Session.participant_id == Participant.id)
                    .where(Session.uid.in_(list(uids)))
                    .distinct()
                )
            )

    def participants(self, study: str, scope: Scope = EVERYTHING) -> list[ParticipantRecord]:
        """A study's participants by code (unknown study: NotFound naming the nearest)."""
        with self.catalog.session() as orm:
            found = self.catalog.study(orm, study)
            return participant_records(orm, scope, Participant.study_id == found.id)

    def add_participant(
        self,
        study: str,
        code: str,
        level: str = "",
        group_label: str = "",
        years_experience: float | None = None,
        handedness: str = "right",
    ) -> ParticipantRecord:
        """A new participant (a pseudonym, never a name); a code already in the study is refused."""
        with self.catalog.session() as orm:
            found = self.catalog.study(orm, study)
            made = self.catalog.add_participant(
                orm, found, code, level, group_label, years_experience, handedness
            )
            return participant_records(orm, EVERYTHING, Participant.id == made.id)[0]

    def sessions(
        self, study: str | None = None, task: str | None = None, status: str | None = None
    ) -> list[SessionRecord]:
        """Sessions in the order they were catalogued, of one study, task or status when given (an
        unknown study is a NotFound naming the nearest)."""
        query = listed_sessions().order_by(Session.id)
        with self.catalog.session() as orm:
            if study is not None:
                self.catalog.study(orm, study)
                query = query.where(Study.name == study)
            if task is not None:
                query = query.where(Task.name == task)
            if status is not None:
                query = query.where(Session.status == status)
            return [SessionRecord(*row) for row in orm.execute(query).all()]

    def scorable_sessions(self, study: str, only_unscored: bool = False) -> list[str]:
        """The uids of a study's scorable sessions (simulator and bench; imported JIGSAWS trials keep
        their own metrics); ``only_unscored``: those without results under this registry version."""
        query = (
            select(Session.uid)
            .join(Participant, Session.participant_id == Participant.id)
            .join(Study, Participant.study_id == Study.id)
            .where(Study.name == study, Session.status.in_(SCORABLE), Session.device != "jigsaws")
            .order_by(Session.id)
        )
        if only_unscored:
            current = select(MetricResult.session_id).where(MetricResult.registry_version == REGISTRY_VERSION)
            query = query.where(Session.id.not_in(current))
        with self.catalog.session() as orm:
            self.catalog.study(orm, study)
            return list(orm.scalars(query))

    def delete_session(self, uid: str) -> str | None:
        """Delete a session's catalog rows (files, metrics, ratings, notes go with it); returns the
        folder its streams were in, for the caller to remove."""
        with self.catalog.session() as orm:
            row = self.catalog.recorded_session(orm, uid)
            directory = row.directory
            orm.delete(row)
        return directory

    # -- the study table -------------------------------------------------------------------
    def study_table(self, study_name: str) -> pd.DataFrame:
        """One row per scored session of a study: ids, label, trial, phase, synthetic flag, task, every
        metric (trials count per task: an analysis takes one task's sessions)."""
        with self.catalog.session() as orm:
            study = self.catalog.study(orm, study_name)
            rows = orm.execute(
                sessions_with(
                    Session.uid,
                    Participant.code,
                    Participant.group_label,
                    Session.trial,
                    Session.phase,
                    synthetic_session(),
                    Task.name,
                    MetricResult.metric,
                    MetricResult.value,
                )
                .join(MetricResult, MetricResult.session_id == Session.id)
                .where(
                    Participant.study_id == study.id,
                    Session.status.in_(SCORABLE),
                    MetricResult.registry_version == REGISTRY_VERSION,
                )
            ).all()
        columns = ["session_id", "participant_id", "label", "trial", "phase", "synthetic", "task"]
        columns += ["metric", "value"]
        long = pd.DataFrame(rows, columns=columns)
        if long.empty:
            raise WrongState(f"study {study_name!r} has no scored sessions", remedy=("score", study_name))
        ids = columns[:7]
        wide = long.set_index([*ids, "metric"])["value"].unstack("metric").reset_index()
        wide.columns.name = None
        names = [m.name for m in REGISTRY if m.name in wide.columns]
        wide = (
            wide[[*ids, *names]]
            .sort_values(["participant_id", "trial"], kind="stable")
            .reset_index(drop=True)
        )
        wide[names] = wide[names].astype(float)
        wide = self._with_ratings(study_name, wide)
        wide["trial"] = wide["trial"].astype(int)
        wide["synthetic"] = wide["synthetic"].astype(bool)
        wide.attrs["registry_version"] = REGISTRY_VERSION
        return wide

    def _with_ratings(self, study_name: str, wide: pd.DataFrame) -> pd.DataFrame:
        """Continuous labels for concurrent validity: years of experience, and per instrument the mean
        over raters of each session's total (column ``<instrument>_total``, e.g. ``grs_total``)."""
        with self.catalog.session() as orm:
            study = self.catalog.study(orm, study_name)
            years = dict(
                orm.execute(
                    select(Participant.code, Participant.years_experience).where(
                        Participant.study_id == study.id
                    )
                ).all()
            )
            totals = orm.execute(
                select(Session.uid, Rating.instrument, Rating.score)
                .join(Rating, Rating.session_id == Session.id)
                .join(Participant, Session.participant_id == Participant.id)
                .where(Participant.study_id == study.id, Rating.item == "total")
            ).all()
        wide["years_experience"] = wide["participant_id"].map(years).astype(float)
        if totals:
            frame = pd.DataFrame(totals, columns=["session_id", "instrument", "score"])
            frame["column"] = (
                frame["instrument"].str.lower().str.replace(r"[^a-z0-9]+", "_", regex=True) + "_total"
            )
            means = frame.groupby(["session_id", "column"])["score"].mean().unstack("column")
            wide = wide.join(means, on="session_id")
        return wide


def participant_records(orm: OrmSession, scope: Scope, where) -> list[ParticipantRecord]:
    """Participants matching ``where`` by code, each with their session count, last session and (for a
    reader who may see accounts) the linked account's user name."""
    query = (
        select(
            Participant.id,
            Participant.study_id,
            Study.name,
            Participant.code,
            Participant.level,
            Participant.group_label,
            Participant.years_experience,
            Participant.handedness,
            Participant.synthetic,
            func.count(Session.id),
            func.max(Session.started_at),
            User.username,
        )
        .join(Study, Participant.study_id == Study.id)
        .outerjoin(Session, Session.participant_id == Participant.id)
        .outerjoin(User, Participant.user_id == User.id)
        .where(where, visible(scope))
        .group_by(Participant.id, Study.name, User.username)
        .order_by(Participant.code)
    )
    return [
        ParticipantRecord(*row[:8], bool(row[8]), row[9], row[10], row[11] if scope.sees_accounts else None)
        for row in orm.execute(query).all()
    ]
