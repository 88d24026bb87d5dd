"""The catalog store's scoped reads: what one reader may see of a study, a participant or a session,
each lookup through :mod:`sessions.catalog.scope` so an id outside the reader's reach answers exactly as
one that does not exist. The dashboard's pages and API compose these with the analysis; they hold no
query of their own."""

from __future__ import annotations

from sqlalchemy import func, select

from metrics.session.registry import REGISTRY_VERSION
from sessions.catalog.engine import Catalog
from sessions.catalog.listing import listed_sessions, participant_records, sessions_with
from sessions.catalog.models import (
    AnalysisDeclaration,
    Annotation,
    MetricResult,
    Participant,
    Rating,
    Rejudgement,
    Session,
    Standard,
    Task,
)
from sessions.catalog.records import (
    AnnotationRecord,
    FileRecord,
    ParticipantRecord,
    SessionFacts,
    SessionRecord,
    StudyRecord,
)
from sessions.catalog.scope import EVERYTHING, Scope, owned_participant, owned_session, owned_study, visible
from sessions.status import SCRIPTED_DEVICE, SessionStatus


class ScopedReads:
    catalog: Catalog

    def study(self, study_id: int, scope: Scope = EVERYTHING, whole: bool = False) -> StudyRecord:
        """A study the reader may see; ``whole`` (its overview, validity, rating queue): staff only."""
        with self.catalog.session() as orm:
            found = owned_study(orm, scope, study_id, whole)
            return StudyRecord(found.id, found.name, found.description)

    def study_participants(self, study_id: int, scope: Scope) -> list[ParticipantRecord]:
        with self.catalog.session() as orm:
            owned_study(orm, scope, study_id)
            return participant_records(orm, scope, Participant.study_id == study_id)

    def sessions_by_status(self, study_id: int, scope: Scope) -> dict[str, int]:
        """How many of a whole study's sessions are in each status (staff)."""
        with self.catalog.session() as orm:
            owned_study(orm, scope, study_id, whole=True)
            return dict(
                orm.execute(
                    select(Session.status, func.count(Session.id))
                    .join(Participant, Session.participant_id == Participant.id)
                    .where(Participant.study_id == study_id)
                    .group_by(Session.status)
                ).all()
            )

    def participant(self, participant_id: int, scope: Scope) -> ParticipantRecord:
        with self.catalog.session() as orm:
            owned_participant(orm, scope, participant_id)
            return participant_records(orm, scope, Participant.id == participant_id)[0]

    def my_participants(self, scope: Scope) -> list[ParticipantRecord]:
        """A trainee's own participants (every participant for anyone else)."""
        with self.catalog.session() as orm:
            return participant_records(orm, scope, visible(scope))

    def participant_sessions(self, participant_id: int, scope: Scope) -> list[SessionRecord]:
        """A participant's sessions in the order they ran."""
        with self.catalog.session() as orm:
            owned_participant(orm, scope, participant_id)
            query = listed_sessions().where(Session.participant_id == participant_id)
            rows = orm.execute(query.order_by(Session.started_at, Session.id)).all()
        return [SessionRecord(*row) for row in rows]

    def visible_sessions(
        self, scope: Scope, study_id: int | None = None, limit: int = 50, offset: int = 0
    ) -> tuple[int, list[SessionRecord]]:
        """(how many the reader may see, a page of them newest first)."""
        query = listed_sessions().where(visible(scope))
        if study_id is not None:
            query = query.where(Participant.study_id == study_id)
        with self.catalog.session() as orm:
            total = orm.scalar(select(func.count()).select_from(query.subquery()))
            rows = orm.execute(
                query.order_by(Session.started_at.desc(), Session.id.desc()).limit(limit).offset(offset)
            ).all()
        return int(total), [SessionRecord(*row) for row in rows]

    def running_sessions(self) -> list[SessionRecord]:
        """Sessions recording now, newest first."""
        query = listed_sessions().where(Session.status == SessionStatus.RUNNING)
        with self.catalog.session() as orm:
            rows = orm.execute(query.order_by(Session.started_at.desc())).all()
        return [SessionRecord(*row) for row in rows]

    def is_running(self, uid: str) -> bool:
        with self.catalog.session() as orm:
            return orm.scalar(select(Session.status).where(Session.uid == uid)) == SessionStatus.RUNNING

    def session_facts(self, uid: str, scope: Scope = EVERYTHING) -> SessionFacts:
        """Everything the catalog holds of a session the reader may see (see :class:`SessionFacts`);
        annotations' authors only for a reader who may see accounts."""
        with self.catalog.session() as orm:
            # the CLI (reading everything) hears the nearest uid; a scoped reader only "not found"
            row = (
                self.catalog.recorded_session(orm, uid)
                if scope is EVERYTHING
                else owned_session(orm, scope, uid)
            )
            listed = orm.execute(listed_sessions().where(Session.id == row.id)).one()
            participant = row.participant
            notes = orm.scalars(
                select(Annotation).where(Annotation.session_id == row.id).order_by(Annotation.id)
            )
            return SessionFacts(
                session=SessionRecord(*listed),
                study_id=participant.study_id,
                participant_id=participant.id,
                group=participant.group_label,
                synthetic=bool(participant.synthetic) or row.device == SCRIPTED_DEVICE,
                task_id=row.task_id,
                clock=row.clock,
                directory=row.directory,
                error=row.error,
                files=tuple(FileRecord(f.name, f.bytes, f.sha256) for f in row.files),
                metrics={
                    m.metric: m.value
                    for m in sorted(row.metrics, key=lambda m: m.id)
                    if m.registry_version == REGISTRY_VERSION
                },
                annotations=tuple(
                    AnnotationRecord(a.time_s, a.text, a.author if scope.sees_accounts else None)
                    for a in notes
                ),
            )

    def rating_queue(self, study_id: int, scope: Scope, rater: str) -> list[tuple[str, str, bool]]:
        """A whole study's sessions for rating: (uid, task, whether ``rater`` has rated it)."""
        with self.catalog.session() as orm:
            owned_study(orm, scope, study_id, whole=True)
            rows = orm.execute(
                sessions_with(Session.uid, Task.name).where(Participant.study_id == study_id)
            ).all()
            rated = set(
                orm.scalars(
                    select(Session.uid)
                    .join(Rating, Rating.session_id == Session.id)
                    .join(Participant, Session.participant_id == Participant.id)
                    .where(Participant.study_id == study_id, Rating.rater == rater)
                )
            )
        return [(uid, task, uid in rated) for uid, task in rows]

    def visible_session_keys(self, scope: Scope) -> list[tuple[str, int, str]]:
        """(uid, study id, task) of every session the reader may see."""
        with self.catalog.session() as orm:
            query = sessions_with(Session.uid, Participant.study_id, Task.name).where(visible(scope))
            return [tuple(row) for row in orm.execute(query).all()]

    def study_fingerprint(self, study_id: int) -> tuple:
        """What changes whenever a study's analysis could: its sessions, results, participants,
        declaration, standards and re-judgings, and the metric registry's version."""
        with self.catalog.session() as orm:
            sessions = orm.execute(
                select(func.count(Session.id), func.max(Session.id), func.max(Session.ended_at))
                .join(Participant, Session.participant_id == Participant.id)
                .where(Participant.study_id == study_id)
            ).one()
            results = orm.execute(select(func.count(MetricResult.id), func.max(MetricResult.id))).one()
            participants = orm.execute(
                select(func.count(Participant.id), func.max(Participant.id)).where(
                    Participant.study_id == study_id
                )
            ).one()
            declared = orm.scalar(
                select(func.max(AnalysisDeclaration.id)).where(AnalysisDeclaration.study_id == study_id)
            )
            standard = orm.scalar(select(func.max(Standard.id)).where(Standard.study_id == study_id))
            rejudged = orm.scalar(
                select(func.max(Rejudgement.id))
                .join(Standard, Standard.id == Rejudgement.standard_id)
                .where(Standard.study_id == study_id)
            )
        return (*sessions, *results, *participants, declared, standard, rejudged, REGISTRY_VERSION)
