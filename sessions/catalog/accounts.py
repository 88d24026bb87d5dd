"""Dashboard accounts, signed-in browsers and station tokens, kept in the catalog.

Passwords are hashed with Argon2id (argon2-cffi's defaults, RFC 9106 low-memory
profile); sign-in tokens and station tokens are random 256-bit values of which the
catalog keeps only the SHA-256, so a copied catalog signs nobody in.
"""

from __future__ import annotations

import functools
import hashlib
import re
import secrets
from datetime import datetime, timedelta

from argon2 import PasswordHasher
from argon2.exceptions import InvalidHashError, VerificationError
from sqlalchemy import delete, select
from sqlalchemy.orm import Session as OrmSession

from sessions.catalog.engine import now
from sessions.catalog.errors import AlreadyExists, CatalogError, NotFound
from sessions.catalog.models import ROLES, LoginSession, Participant, StationToken, User

MIN_PASSWORD_LENGTH = 10
USERNAME_PATTERN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.@-]{1,63}$")
STATION_PATTERN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_-]{0,63}$")
_HASHER = PasswordHasher()


@functools.cache
def _dummy_hash() -> str:
    """Verified against when a username does not exist, so a wrong name costs as much time as a wrong
    password. Made at the first sign-in (whatever its name), not at import: a hash costs ~0.1 s, which
    every process that opens a catalog would pay."""
    return _HASHER.hash(secrets.token_hex(16))


class AccountError(CatalogError):
    """An account or token request that cannot be carried out (bad name, weak password, unknown user)."""


class AccountConflict(AccountError, AlreadyExists):
    """An account, link or station token that already exists."""


class AccountNotFound(AccountError, NotFound):
    """No user or station token of that name or id."""


def token_digest(token: str) -> str:
    return hashlib.sha256(token.encode()).hexdigest()


def check_role(role: str) -> str:
    if role not in ROLES:
        raise AccountError(f"role {role!r} is not one of {', '.join(ROLES)}")
    return role


def check_password(password: str) -> str:
    if len(password) < MIN_PASSWORD_LENGTH:
        raise AccountError(f"password must have at least {MIN_PASSWORD_LENGTH} characters")
    return password


def create_user(orm: OrmSession, username: str, password: str, role: str) -> User:
    """A new active account; the password is stored only as its Argon2id hash."""
    if not USERNAME_PATTERN.match(username):
        raise AccountError(
            f"username {username!r} must be 2-64 letters, digits or . _ @ -, starting with a letter or digit"
        )
    check_role(role)
    check_password(password)
    if orm.scalar(select(User.id).where(User.username == username)) is not None:
        raise AccountConflict(f"user {username!r} already exists")
    user = User(
        username=username, password_hash=_HASHER.hash(password), role=role, active=True, created_at=now()
    )
    orm.add(user)
    orm.flush()
    return user


def user_named(orm: OrmSession, username: str) -> User:
    found = orm.scalar(select(User).where(User.username == username))
    if found is None:
        raise AccountNotFound("user", username, list(orm.scalars(select(User.username))))
    return found


def set_password(orm: OrmSession, user: User, password: str) -> None:
    user.password_hash = _HASHER.hash(check_password(password))
    orm.execute(delete(LoginSession).where(LoginSession.user_id == user.id))  # signs every browser out


def set_active(orm: OrmSession, user: User, active: bool) -> None:
    """Activate or deactivate an account; deactivation ends every sign-in, so re-activating it later
    does not bring the old ones back."""
    user.active = active
    if not active:
        orm.execute(delete(LoginSession).where(LoginSession.user_id == user.id))


def authenticate(orm: OrmSession, username: str, password: str) -> User | None:
    """The active user with this name and password, or None (same work whether or not the name exists)."""
    user = orm.scalar(select(User).where(User.username == username))
    dummy = _dummy_hash()  # made (once) whether or not the name exists
    try:
        _HASHER.verify(user.password_hash if user else dummy, password)
    except (VerificationError, InvalidHashError):
        return None
    if user is None or not user.active:
        return None
    if _HASHER.check_needs_rehash(user.password_hash):
        user.password_hash = _HASHER.hash(password)
    return user


def link_participant(orm: OrmSession, user: User, participant: Participant) -> None:
    """Let a trainee account see this participant's sessions."""
    if user.role != "trainee":
        raise AccountError(
            f"only trainee accounts are linked to participants; {user.username!r} is {user.role}"
        )
    if participant.user_id not in (None, user.id):
        raise AccountConflict(f"participant {participant.code!r} is already linked to another account")
    participant.user_id = user.id


def set_participants(orm: OrmSession, user: User, participants: list[Participant]) -> None:
    """Make ``participants`` exactly the ones this trainee account sees (links can be changed later)."""
    for linked in orm.scalars(select(Participant).where(Participant.user_id == user.id)):
        if linked not in participants:
            linked.user_id = None
    for participant in participants:
        link_participant(orm, user, participant)


def participants_by_code(orm: OrmSession, catalog, written: list[str]) -> list[Participant]:
    """Participants written ``STUDY:CODE`` (the codes a supervisor knows), each resolved or refused:
    a wrong form is an AccountError, an unknown study or code the catalog's NotFound."""
    found = []
    for text in written:
        study_name, separator, code = text.strip().rpartition(":")
        if not separator or not study_name or not code:
            raise AccountError(f"participant {text!r} must be written STUDY:CODE, e.g. synthetic-demo:T02")
        found.append(catalog.participant(orm, catalog.study(orm, study_name), code))
    return found


# -- signed-in browsers -------------------------------------------------------------------
def start_login(orm: OrmSession, user: User, lifetime: timedelta) -> tuple[str, str]:
    """(cookie token, CSRF token) of a new sign-in; expired sign-ins of everybody are removed."""
    orm.execute(delete(LoginSession).where(LoginSession.expires_at < now()))
    token, csrf = secrets.token_urlsafe(32), secrets.token_urlsafe(32)
    orm.add(
        LoginSession(
            token_sha256=token_digest(token),
            user_id=user.id,
            csrf_token=csrf,
            created_at=now(),
            expires_at=now() + lifetime,
        )
    )
    return token, csrf


def login_for(orm: OrmSession, token: str, at: datetime | None = None) -> tuple[User, LoginSession] | None:
    found = orm.execute(
        select(User, LoginSession)
        .join(LoginSession, LoginSession.user_id == User.id)
        .where(LoginSession.token_sha256 == token_digest(token))
    ).first()
    if found is None:
        return None
    user, login = found
    if login.expires_at < (at or now()) or not user.active:
        return None
    return user, login


def end_login(orm: OrmSession, token: str) -> None:
    orm.execute(delete(LoginSession).where(LoginSession.token_sha256 == token_digest(token)))


# -- station tokens -------------------------------------------------------------------------
def create_station_token(orm: OrmSession, station: str) -> tuple[StationToken, str]:
    """A new ingest token for ``station``; the token is returned once and stored only as SHA-256."""
    if not STATION_PATTERN.match(station):
        raise AccountError(f"station name {station!r} must be 1-64 letters, digits, '-' or '_'")
    existing = orm.scalar(select(StationToken).where(StationToken.station == station))
    token = secrets.token_urlsafe(32)
    if existing is not None:
        if existing.revoked_at is None:
            raise AccountConflict(f"station {station!r} already has a token; revoke it first")
        orm.delete(existing)
        orm.flush()
    row = StationToken(station=station, token_sha256=token_digest(token), created_at=now())
    orm.add(row)
    orm.flush()
    return row, token


def station_for_token(orm: OrmSession, token: str) -> str | None:
    row = orm.scalar(
        select(StationToken).where(
            StationToken.token_sha256 == token_digest(token), StationToken.revoked_at.is_(None)
        )
    )
    return row.station if row else None


def revoke_station_token(orm: OrmSession, token_id: int) -> StationToken:
    row = orm.get(StationToken, token_id)
    if row is None:
        raise AccountNotFound("station token", token_id)
    row.revoked_at = row.revoked_at or now()
    return row
