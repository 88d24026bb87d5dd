"""The catalog: one object over a SQLAlchemy engine, SQLite by default or PostgreSQL by URL.

SQLite runs in WAL mode with a busy timeout and foreign keys on, so several
processes (a station recording, a supervisor scoring) can write at once. The
schema is created and upgraded by the Alembic migrations in ``sessions/catalog/migrations``.
"""

from __future__ import annotations

import fcntl
import math
import random
import time
import uuid
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from datetime import UTC, datetime
from pathlib import Path

from alembic import command
from alembic.config import Config
from sqlalchemy import create_engine, event, func, select, text
from sqlalchemy.engine import Engine, make_url
from sqlalchemy.exc import ArgumentError, IntegrityError, NoSuchModuleError, OperationalError
from sqlalchemy.orm import Session as OrmSession
from sqlalchemy.orm import sessionmaker

from metrics.session.registry import REGISTRY_VERSION
from recorder.layout import sha256_of
from sessions.catalog.errors import AlreadyExists, CatalogError, NotFound, WrongState
from sessions.catalog.groups import group_name
from sessions.catalog.models import MetricResult, Participant, Session, StreamFile, Study, Task

MIGRATIONS = Path(__file__).with_name("migrations")
SQLITE_BUSY_TIMEOUT_MS = 30_000
TRIAL_ATTEMPTS = 50  # inserts racing for the next trial number: each conflict retries
MIGRATION_LOCK_KEY = 0x76617363  # "vasc": the PostgreSQL advisory lock every migrating process takes


def now() -> datetime:
    return datetime.now(UTC).replace(tzinfo=None)


def new_uid(prefix: str = "S") -> str:
    return f"{prefix}-{uuid.uuid4().hex[:12]}"


def _normalise(url: str) -> str:
    if url.startswith("postgresql://") or url.startswith("postgres://"):
        return "postgresql+psycopg://" + url.split("://", 1)[1]
    return url


def make_engine(url: str) -> Engine:
    try:
        parsed = make_url(_normalise(url))
    except ArgumentError:
        raise CatalogError(
            f"database URL {url!r} is not valid; use sqlite:///path/catalog.sqlite or postgresql://user@host/db"
        ) from None
    if parsed.get_backend_name() not in ("sqlite", "postgresql"):
        raise CatalogError(f"database URL {url!r}: only sqlite and postgresql catalogs are supported")
    try:
        if parsed.get_backend_name() == "sqlite":
            if parsed.database:
                Path(parsed.database).parent.mkdir(parents=True, exist_ok=True)
            engine = create_engine(parsed, connect_args={"timeout": SQLITE_BUSY_TIMEOUT_MS / 1000})

            @event.listens_for(engine, "connect")
            def _sqlite_pragmas(connection, _record):
                cursor = connection.cursor()
                cursor.execute("PRAGMA journal_mode=WAL")
                cursor.execute(f"PRAGMA busy_timeout={SQLITE_BUSY_TIMEOUT_MS}")
                cursor.execute("PRAGMA foreign_keys=ON")
                cursor.execute("PRAGMA synchronous=NORMAL")
                cursor.close()

            return engine
        return create_engine(parsed, pool_pre_ping=True)
    except NoSuchModuleError as error:
        raise CatalogError(f"database URL {url!r}: {error}") from None


def alembic_config(engine_connection) -> Config:
    config = Config()
    config.set_main_option("script_location", str(MIGRATIONS))
    config.attributes["connection"] = engine_connection
    return config


@contextmanager
def _sqlite_migration_lock(engine: Engine) -> Iterator[None]:
    """An exclusive lock on ``<database>.migrate-lock`` while a file-backed SQLite catalog migrates."""
    database = engine.url.database if engine.dialect.name == "sqlite" else None
    if not database or database == ":memory:":
        yield
        return
    with open(f"{database}.migrate-lock", "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
        yield


class Catalog:
    """Open (and migrate to the newest schema) the catalog at ``url``."""

    def __init__(self, url: str, migrate: bool = True) -> None:
        self.url = url
        self.engine = make_engine(url)
        self._sessions = sessionmaker(self.engine, expire_on_commit=False)
        if migrate:
            self.upgrade()

    def upgrade(self) -> None:
        """Migrate to the newest schema, one process at a time: processes opening a new catalog at
        once wait for the first, then find it migrated (SQLite: a lock file beside the database;
        PostgreSQL: an advisory lock held for the migrating transaction)."""
        try:
            with _sqlite_migration_lock(self.engine), self.engine.begin() as connection:
                if self.engine.dialect.name == "postgresql":
                    lock = text("SELECT pg_advisory_xact_lock(:key)")
                    connection.execute(lock, {"key": MIGRATION_LOCK_KEY})
                command.upgrade(alembic_config(connection), "head")
        except OperationalError as error:
            reason = str(error.orig).strip().splitlines()[0] if error.orig else str(error)
            raise CatalogError(f"cannot open the catalog at {self.display_url}: {reason}") from None

    @property
    def display_url(self) -> str:
        return make_url(_normalise(self.url)).render_as_string(hide_password=True)

    @contextmanager
    def session(self) -> Iterator[OrmSession]:
        """A transaction: committed on success, rolled back on any error."""
        with self._sessions() as orm, orm.begin():
            yield orm

    def close(self) -> None:
        self.engine.dispose()

    # -- lookups and creation ----------------------------------------------------------
    def study(self, orm: OrmSession, name: str, create: bool = False, description: str = "") -> Study:
        found = orm.scalar(select(Study).where(Study.name == name))
        if found is None:
            if not create:
                raise NotFound("study", name, list(orm.scalars(select(Study.name))), noun="study named")
            found = Study(name=name, description=description, created_at=now())
            orm.add(found)
            orm.flush()
        return found

    def recorded_session(self, orm: OrmSession, uid: str) -> Session:
        """The session with this uid; :class:`NotFound` naming it when there is none."""
        found = orm.scalar(select(Session).where(Session.uid == uid))
        if found is None:
            raise NotFound("session", uid)
        return found

    def participant(self, orm: OrmSession, study: Study, code: str) -> Participant:
        found = orm.scalar(
            select(Participant).where(Participant.study_id == study.id, Participant.code == code)
        )
        if found is None:
            codes = list(orm.scalars(select(Participant.code).where(Participant.study_id == study.id)))
            raise NotFound("participant", code, codes, where=f" in study {study.name!r}")
        return found

    def add_participant(
        self,
        orm: OrmSession,
        study: Study,
        code: str,
        level: str = "",
        group_label: str = "",
        years_experience: float | None = None,
        handedness: str = "right",
        synthetic: bool = False,
    ) -> Participant:
        if orm.scalar(select(Participant).where(Participant.study_id == study.id, Participant.code == code)):
            raise AlreadyExists(f"participant {code!r} already exists in study {study.name!r}")
        level = group_name(level, study.custom_groups or (), "level", study.name)
        group_label = group_name(group_label, study.custom_groups or (), "group", study.name) or level
        participant = Participant(
            study_id=study.id,
            code=code,
            level=level,
            group_label=group_label,
            years_experience=years_experience,
            handedness=handedness,
            synthetic=synthetic,
            created_at=now(),
        )
        orm.add(participant)
        orm.flush()
        return participant

    def add_session(self, fields: dict, fill: Callable[[OrmSession, Session], None] | None = None) -> Session:
        """Insert a session row in its own transaction; returns it.

        ``fields["trial"]`` None: the next trial number of its participant on its task, allocated
        inside the inserting transaction (the unique (participant, task, trial) constraint turns a
        concurrent run's claim of the same number into a retry, never a duplicate). ``fill`` adds
        the session's other rows in the same transaction. An explicit trial that exists is refused."""
        allocate = fields.get("trial") is None
        for attempt in range(TRIAL_ATTEMPTS):
            try:
                with self.session() as orm:
                    values = dict(fields)
                    if allocate:
                        values["trial"] = self.next_trial(orm, values["participant_id"], values["task_id"])
                    row = Session(**values)
                    orm.add(row)
                    orm.flush()
                    if fill is not None:
                        fill(orm, row)
                return row
            except (IntegrityError, OperationalError) as error:
                if not _lost_a_race(error):
                    raise
                if not allocate:
                    raise AlreadyExists(
                        f"trial {fields['trial']} of this participant on this task is already catalogued"
                    ) from None
                time.sleep(random.uniform(0.0, 0.01 * (attempt + 1)))
        raise WrongState(f"no free trial number after {TRIAL_ATTEMPTS} attempts; too many runs at once")

    @staticmethod
    def next_trial(orm: OrmSession, participant_id: int, task_id: int) -> int:
        """One more than the participant's highest trial on the task (1 for the first)."""
        highest = orm.scalar(
            select(func.max(Session.trial)).where(
                Session.participant_id == participant_id, Session.task_id == task_id
            )
        )
        return (highest or 0) + 1

    def ensure_task(self, name: str, scenario: str, parameters: dict | None = None) -> int:
        """The id of task ``name``, its row created in a transaction of its own when it is missing.
        Processes that run a new task for the first time at once all get the one row: the unique
        name turns a concurrent creation into a retry that finds it."""
        for attempt in range(TRIAL_ATTEMPTS):
            try:
                with self.session() as orm:
                    return self.task(orm, name, scenario, parameters).id
            except (IntegrityError, OperationalError) as error:
                if not (
                    _lost_a_race(error) or "tasks.name" in str(error.orig) or "tasks_name" in str(error.orig)
                ):
                    raise
                time.sleep(random.uniform(0.0, 0.01 * (attempt + 1)))
        raise WrongState(
            f"task {name!r} could not be created after {TRIAL_ATTEMPTS} attempts; too many runs at once"
        )

    def task(
        self, orm: OrmSession, name: str, scenario: str | None = None, parameters: dict | None = None
    ) -> Task:
        found = orm.scalar(select(Task).where(Task.name == name))
        if found is None:
            if scenario is None:
                raise NotFound("task", name, list(orm.scalars(select(Task.name))), noun="task named")
            found = Task(name=name, scenario=scenario, parameters=parameters or {})
            orm.add(found)
            orm.flush()
        return found


def _lost_a_race(error: IntegrityError | OperationalError) -> bool:
    """A trial-number conflict with a concurrent insert (or SQLite refusing a stale writer)."""
    text_ = str(error.orig)
    if isinstance(error, OperationalError):
        return "database is locked" in text_
    return "uq_session_trial" in text_ or "sessions.participant_id, sessions.task_id, sessions.trial" in text_


def stream_file(session_id: int, path: Path) -> StreamFile:
    """The catalog row of one stream file: name, SHA-256 and size."""
    return StreamFile(
        session_id=session_id, name=path.name, sha256=sha256_of(path), bytes=path.stat().st_size
    )


def metric_results(session_id: int, values: dict[str, float]) -> list[MetricResult]:
    """Metric rows of one session under the current registry version (NaN stored as NULL)."""

    return [
        MetricResult(
            session_id=session_id,
            metric=name,
            value=None if math.isnan(value) else float(value),
            registry_version=REGISTRY_VERSION,
        )
        for name, value in values.items()
    ]
