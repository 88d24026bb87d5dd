"""The catalog store's administration: accounts with the participants they see (written STUDY:CODE,
the codes a supervisor knows), station ingest tokens and studies. Errors are the catalog's, by type
(:class:`sessions.catalog.NotFound`, :class:`AlreadyExists`, :class:`WrongState`), with messages
that name the input and carry no front-end's advice.
"""

from __future__ import annotations

from collections.abc import Sequence
from datetime import timedelta
from typing import Any

from sqlalchemy import select

from sessions.catalog import accounts
from sessions.catalog.engine import Catalog
from sessions.catalog.errors import AlreadyExists, NotFound, WrongState
from sessions.catalog.models import Participant, StationToken, Study, User
from sessions.catalog.records import StationRecord, StudyRecord, UserRecord


class Administration:
    """Accounts, sign-ins, station tokens and studies of one catalog."""

    catalog: Catalog

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

    def user_named(self, username: str) -> UserRecord:
        with self.catalog.session() as orm:
            return _user_record(orm, accounts.user_named(orm, username))

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

    # -- sign-ins ------------------------------------------------------------------------
    def sign_in(
        self, username: str, password: str, lifetime: timedelta
    ) -> tuple[UserRecord, str, str] | None:
        """(the account, its new sign-in token, that sign-in's CSRF token), or None for a wrong user
        name or password (the same answer for both)."""
        with self.catalog.session() as orm:
            user = accounts.authenticate(orm, username, password)
            if user is None:
                return None
            token, csrf = accounts.start_login(orm, user, lifetime)
            return _user_record(orm, user), token, csrf

    def signed_in(self, token: str) -> tuple[UserRecord, str] | None:
        """The account of a live sign-in token and its CSRF token; None when unknown or expired."""
        with self.catalog.session() as orm:
            found = accounts.login_for(orm, token)
            if found is None:
                return None
            user, login = found
            return _user_record(orm, user), login.csrf_token

    def sign_out(self, token: str) -> None:
        with self.catalog.session() as orm:
            accounts.end_login(orm, token)

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

    def station_for_token(self, token: str) -> str | None:
        """The station a live ingest token belongs to, or None."""
        with self.catalog.session() as orm:
            return accounts.station_for_token(orm, token)

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
