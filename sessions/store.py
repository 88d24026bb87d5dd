"""The catalog as a store with a domain API: each method runs its own transaction and returns plain
frozen values, never ORM rows, so a front-end (the CLI, the dashboard's API and pages) states no rule
of its own and two front-ends cannot disagree.

This first part owns administration: accounts with the participants they see (written STUDY:CODE,
the codes a supervisor knows), station ingest tokens and studies. Errors are the catalog's, by type
(:class:`sessions.catalog.NotFound`, :class:`AlreadyExists`, :class:`WrongState`), with messages
that name the input and carry no front-end's advice.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass
from datetime import datetime
from typing import Any

import pandas as pd
from sqlalchemy import select

from metrics.registry import REGISTRY, REGISTRY_VERSION
from sessions import accounts
from sessions.catalog import AlreadyExists, Catalog, NotFound, WrongState
from sessions.models import MetricResult, Participant, Rating, Session, StationToken, Study, Task, User
from sessions.status import SCORABLE


@dataclass(frozen=True)
class UserRecord:
    """An account as every front-end shows it: linked participants as ids and as STUDY:CODE."""

    id: int
    username: str
    role: str
    active: bool
    created_at: datetime
    participant_ids: tuple[int, ...]
    participants: tuple[str, ...]

    def as_dict(self) -> dict[str, Any]:
        return {
            **asdict(self),
            "participant_ids": list(self.participant_ids),
            "participants": list(self.participants),
        }


@dataclass(frozen=True)
class StationRecord:
    """A station's ingest token as listed (the token itself is shown once, when issued)."""

    id: int
    station: str
    created_at: datetime
    revoked_at: datetime | None

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class SessionRecord:
    """A session as a listing shows it: its catalog id, uid, study, participant code, task, trial,
    phase, device, status and when it ran."""

    id: int
    uid: str
    study: str
    participant: str
    task: str
    trial: int
    phase: str
    device: str
    status: str
    started_at: datetime
    ended_at: datetime | None


@dataclass(frozen=True)
class StudyRecord:
    id: int
    name: str
    description: str

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


class CatalogStore:
    """Administration of one catalog (see the module docstring)."""

    def __init__(self, catalog: Catalog) -> None:
        self.catalog = catalog

    # -- accounts -------------------------------------------------------------------------
    def users(self) -> list[UserRecord]:
        """Every account, by user name."""
        with self.catalog.session() as orm:
            return [_user_record(orm, user) for user in orm.scalars(select(User).order_by(User.username))]

    def create_user(
        self,
        username: str,
        password: str,
        role: str,
        participants: Sequence[str] = (),
        participant_ids: Sequence[int] = (),
    ) -> UserRecord:
        """A new account linked to ``participants`` (STUDY:CODE) and ``participant_ids``; every
        participant is resolved before the account exists, so an unknown one creates nothing."""
        with self.catalog.session() as orm:
            chosen = accounts.participants_by_code(orm, self.catalog, list(participants))
            for participant_id in participant_ids:
                participant = orm.get(Participant, participant_id)
                if participant is None:
                    raise NotFound("participant", participant_id)
                chosen.append(participant)
            user = accounts.create_user(orm, username, password, role)
            for participant in chosen:
                accounts.link_participant(orm, user, participant)
            orm.flush()
            return _user_record(orm, user)

    def set_user_participants(self, user_id: int, participants: Sequence[str]) -> UserRecord:
        """Make ``participants`` (STUDY:CODE) exactly the ones a trainee account sees."""
        with self.catalog.session() as orm:
            user = _user(orm, user_id)
            accounts.set_participants(
                orm, user, accounts.participants_by_code(orm, self.catalog, list(participants))
            )
            orm.flush()
            return _user_record(orm, user)

    def change_user(
        self,
        user_id: int,
        acting_user_id: int | None = None,
        role: str | None = None,
        active: bool | None = None,
        password: str | None = None,
    ) -> UserRecord:
        """Change an account's role, state or password; an admin (``acting_user_id``) can neither
        deactivate nor demote their own account."""
        with self.catalog.session() as orm:
            user = _user(orm, user_id)
            if user.id == acting_user_id and (active is False or (role and role != "admin")):
                raise WrongState("an admin cannot deactivate or demote their own account")
            if role is not None:
                user.role = accounts.check_role(role)
            if active is not None:
                accounts.set_active(orm, user, active)
            if password is not None:
                accounts.set_password(orm, user, password)
            return _user_record(orm, user)

    def participant_codes(self) -> list[str]:
        """Every participant as STUDY:CODE (the account form's picker)."""
        with self.catalog.session() as orm:
            rows = orm.execute(
                select(Study.name, Participant.code).join(Participant, Participant.study_id == Study.id)
            ).all()
        return sorted(f"{study}:{code}" for study, code in rows)

    # -- sessions -------------------------------------------------------------------------
    def sessions(
        self, study: str | None = None, task: str | None = None, status: str | None = None
    ) -> list[SessionRecord]:
        """Sessions in the order they were catalogued, of one study, task or status when given (an
        unknown study is a NotFound naming the nearest)."""
        query = (
            _sessions_with(
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
            .join(Study, Participant.study_id == Study.id)
            .order_by(Session.id)
        )
        with self.catalog.session() as orm:
            if study is not None:
                self.catalog.study(orm, study)
                query = query.where(Study.name == study)
            if task is not None:
                query = query.where(Task.name == task)
            if status is not None:
                query = query.where(Session.status == status)
            return [SessionRecord(*row) for row in orm.execute(query).all()]

    # -- the study table -------------------------------------------------------------------
    def study_table(self, study_name: str) -> pd.DataFrame:
        """One row per scored session of a study: ids, label, trial, phase, synthetic flag, task, every
        metric (trials count per task: an analysis takes one task's sessions)."""
        with self.catalog.session() as orm:
            study = self.catalog.study(orm, study_name)
            rows = orm.execute(
                _sessions_with(
                    Session.uid,
                    Participant.code,
                    Participant.group_label,
                    Session.trial,
                    Session.phase,
                    Participant.synthetic,
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
            raise WrongState(f"study {study_name!r} has no scored sessions; run `vascsim score` first")
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

    # -- stations -------------------------------------------------------------------------
    def stations(self) -> list[StationRecord]:
        """Every station token, by station name."""
        with self.catalog.session() as orm:
            rows = orm.scalars(select(StationToken).order_by(StationToken.station))
            return [StationRecord(r.id, r.station, r.created_at, r.revoked_at) for r in rows]

    def issue_station_token(self, station: str) -> dict[str, Any]:
        """A new ingest token for ``station``: {id, station, token} (the token is shown this once;
        only its digest is stored)."""
        with self.catalog.session() as orm:
            row, token = accounts.create_station_token(orm, station)
            orm.flush()
            return {"id": row.id, "station": row.station, "token": token}

    def revoke_station_token(self, token_id: int) -> StationRecord:
        with self.catalog.session() as orm:
            row = accounts.revoke_station_token(orm, token_id)
            return StationRecord(row.id, row.station, row.created_at, row.revoked_at)

    # -- studies --------------------------------------------------------------------------
    def create_study(self, name: str, description: str = "") -> StudyRecord:
        """A new study; a name already taken is refused."""
        with self.catalog.session() as orm:
            if orm.scalar(select(Study.id).where(Study.name == name)) is not None:
                raise AlreadyExists(f"study {name!r} already exists")
            study = self.catalog.study(orm, name, create=True, description=description)
            return StudyRecord(study.id, study.name, study.description)


def _sessions_with(*columns):
    """A query of ``columns`` over sessions joined to their participant and task."""
    return (
        select(*columns)
        .join(Participant, Session.participant_id == Participant.id)
        .join(Task, Session.task_id == Task.id)
    )


def _user(orm, user_id: int) -> User:
    user = orm.get(User, user_id)
    if user is None:
        raise NotFound("user", user_id)
    return user


def _user_record(orm, user: User) -> UserRecord:
    linked = orm.execute(
        select(Participant.id, Study.name, Participant.code)
        .join(Study, Participant.study_id == Study.id)
        .where(Participant.user_id == user.id)
        .order_by(Study.name, Participant.code)
    ).all()
    return UserRecord(
        user.id,
        user.username,
        user.role,
        user.active,
        user.created_at,
        tuple(pid for pid, _, _ in linked),
        tuple(f"{study}:{code}" for _, study, code in linked),
    )
