"""The catalog's tables (SQLAlchemy 2). Migrations in ``sessions/catalog/migrations`` must match them."""

from __future__ import annotations

from datetime import datetime

from sqlalchemy import (
    JSON,
    Boolean,
    DateTime,
    Float,
    ForeignKey,
    Integer,
    String,
    Text,
    UniqueConstraint,
)
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column, relationship

ROLES = ("admin", "supervisor", "researcher", "trainee")


class Base(DeclarativeBase):
    pass


class Study(Base):
    """A study or course: the set of participants and sessions analysed together."""

    __tablename__ = "studies"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    name: Mapped[str] = mapped_column(String(200), unique=True)
    description: Mapped[str] = mapped_column(Text, default="")
    created_at: Mapped[datetime] = mapped_column(DateTime)
    # groups this study declared beyond the standard ones (sessions.catalog.groups), lower-case
    custom_groups: Mapped[list] = mapped_column(JSON, default=list, server_default="[]")
    participants: Mapped[list[Participant]] = relationship(
        back_populates="study", cascade="all, delete-orphan"
    )
    analyses: Mapped[list[AnalysisDeclaration]] = relationship(
        cascade="all, delete-orphan", passive_deletes=True, order_by="AnalysisDeclaration.version"
    )


class AnalysisDeclaration(Base):
    """One version of a study's declared analysis (:class:`metrics.study.analysis.StudySettings` as JSON).

    Versions are never edited: a change is a new row, so who changed what, and when, stays readable.
    """

    __tablename__ = "analysis_declarations"
    __table_args__ = (UniqueConstraint("study_id", "version", name="uq_analysis_version"),)
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    study_id: Mapped[int] = mapped_column(ForeignKey("studies.id", ondelete="CASCADE"), index=True)
    version: Mapped[int] = mapped_column(Integer)
    settings: Mapped[dict] = mapped_column(JSON)
    author: Mapped[str] = mapped_column(String(100))
    note: Mapped[str] = mapped_column(Text, default="")
    created_at: Mapped[datetime] = mapped_column(DateTime)


class Standard(Base):
    """One version of a study's standard on one task: the pass marks as they were set, from which
    experts and sessions, by whom and when (sessions.scoring.standards). Never edited: a new version is a
    new row, and analyses judge against the newest instead of recomputing marks from today's data."""

    __tablename__ = "standards"
    __table_args__ = (UniqueConstraint("study_id", "task", "version", name="uq_standard_version"),)
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    study_id: Mapped[int] = mapped_column(ForeignKey("studies.id", ondelete="CASCADE"), index=True)
    task: Mapped[str] = mapped_column(String(100))
    version: Mapped[int] = mapped_column(Integer)
    rule: Mapped[str] = mapped_column(String(32))
    marks: Mapped[list] = mapped_column(JSON)  # per metric: metric, benchmark (SI), better, pass_if, experts
    experts: Mapped[list] = mapped_column(JSON)  # participant codes
    sessions: Mapped[list] = mapped_column(JSON)  # the expert sessions' uids
    min_experts: Mapped[int] = mapped_column(Integer)
    registry_version: Mapped[str] = mapped_column(String(16))
    analysis_version: Mapped[int | None] = mapped_column(Integer, nullable=True)
    set_by: Mapped[str] = mapped_column(String(100))
    set_at: Mapped[datetime] = mapped_column(DateTime)
    note: Mapped[str] = mapped_column(Text, default="")


class Verdict(Base):
    """A session's verdict under one version of its study's standard, kept as it was given: setting a
    newer version does not change it; only an explicit re-judging (a :class:`Rejudgement`) does."""

    __tablename__ = "verdicts"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    session_id: Mapped[int] = mapped_column(ForeignKey("sessions.id", ondelete="CASCADE"), unique=True)
    standard_id: Mapped[int] = mapped_column(ForeignKey("standards.id", ondelete="CASCADE"), index=True)
    passed: Mapped[bool] = mapped_column(Boolean)
    judged_at: Mapped[datetime] = mapped_column(DateTime)
    how: Mapped[str] = mapped_column(String(300))  # e.g. "recorded under v2", "re-judged under v3 by ..."


class Rejudgement(Base):
    """The log of re-judging a task's sessions under a newer standard: who, when, why, how many."""

    __tablename__ = "rejudgements"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    standard_id: Mapped[int] = mapped_column(ForeignKey("standards.id", ondelete="CASCADE"), index=True)
    judged_by: Mapped[str] = mapped_column(String(100))
    judged_at: Mapped[datetime] = mapped_column(DateTime)
    reason: Mapped[str] = mapped_column(Text)
    sessions: Mapped[int] = mapped_column(Integer)
    changed: Mapped[int] = mapped_column(Integer)  # verdicts that flipped


class Participant(Base):
    """A pseudonymous participant: ``code`` is the only identifier stored."""

    __tablename__ = "participants"
    __table_args__ = (UniqueConstraint("study_id", "code", name="uq_participant_code"),)
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    study_id: Mapped[int] = mapped_column(ForeignKey("studies.id", ondelete="CASCADE"), index=True)
    code: Mapped[str] = mapped_column(String(64))
    level: Mapped[str] = mapped_column(String(32), default="")  # self-reported: expert, trainee, novice...
    years_experience: Mapped[float | None] = mapped_column(Float, nullable=True)
    handedness: Mapped[str] = mapped_column(String(8), default="right")
    group_label: Mapped[str] = mapped_column(String(64), default="")
    synthetic: Mapped[bool] = mapped_column(Boolean, default=False)
    created_at: Mapped[datetime] = mapped_column(DateTime)
    # the trainee account that may see this participant's sessions (never shown to researchers)
    user_id: Mapped[int | None] = mapped_column(
        ForeignKey("users.id", ondelete="SET NULL", name="fk_participants_user_id"), nullable=True, index=True
    )
    study: Mapped[Study] = relationship(back_populates="participants")
    sessions: Mapped[list[Session]] = relationship(back_populates="participant", cascade="all, delete-orphan")


class Task(Base):
    """A task / scenario: mesh, materials, model parameters (as JSON)."""

    __tablename__ = "tasks"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    name: Mapped[str] = mapped_column(String(100), unique=True)
    scenario: Mapped[str] = mapped_column(String(100))
    parameters: Mapped[dict] = mapped_column(JSON, default=dict)


class Session(Base):
    """One attempt: who, what, when, how, and where its streams are."""

    __tablename__ = "sessions"
    __table_args__ = (UniqueConstraint("participant_id", "task_id", "trial", name="uq_session_trial"),)
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    uid: Mapped[str] = mapped_column(String(64), unique=True)
    participant_id: Mapped[int] = mapped_column(ForeignKey("participants.id", ondelete="CASCADE"), index=True)
    task_id: Mapped[int] = mapped_column(ForeignKey("tasks.id"), index=True)
    device: Mapped[str] = mapped_column(String(100))
    clock: Mapped[str] = mapped_column(String(16))
    trial: Mapped[int] = mapped_column(Integer)
    phase: Mapped[str] = mapped_column(String(16), default="practice")
    status: Mapped[str] = mapped_column(String(16), index=True)
    started_at: Mapped[datetime] = mapped_column(DateTime)
    ended_at: Mapped[datetime | None] = mapped_column(DateTime, nullable=True)
    directory: Mapped[str] = mapped_column(Text)
    error: Mapped[str] = mapped_column(Text, default="")
    participant: Mapped[Participant] = relationship(back_populates="sessions")
    task: Mapped[Task] = relationship()
    files: Mapped[list[StreamFile]] = relationship(cascade="all, delete-orphan", passive_deletes=True)
    metrics: Mapped[list[MetricResult]] = relationship(cascade="all, delete-orphan", passive_deletes=True)
    stitches: Mapped[list[StitchResult]] = relationship(cascade="all, delete-orphan", passive_deletes=True)
    ratings: Mapped[list[Rating]] = relationship(cascade="all, delete-orphan", passive_deletes=True)
    annotations: Mapped[list[Annotation]] = relationship(cascade="all, delete-orphan", passive_deletes=True)


class StreamFile(Base):
    __tablename__ = "stream_files"
    __table_args__ = (UniqueConstraint("session_id", "name", name="uq_stream_file"),)
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    session_id: Mapped[int] = mapped_column(ForeignKey("sessions.id", ondelete="CASCADE"), index=True)
    name: Mapped[str] = mapped_column(String(200))
    sha256: Mapped[str] = mapped_column(String(64))
    bytes: Mapped[int] = mapped_column(Integer)


class MetricResult(Base):
    __tablename__ = "metric_results"
    __table_args__ = (UniqueConstraint("session_id", "metric", "registry_version", name="uq_metric_result"),)
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    session_id: Mapped[int] = mapped_column(ForeignKey("sessions.id", ondelete="CASCADE"), index=True)
    metric: Mapped[str] = mapped_column(String(100))
    value: Mapped[float | None] = mapped_column(Float, nullable=True)
    registry_version: Mapped[str] = mapped_column(String(16))
    # "computed" here from the session's streams, or "imported" from a bundle and not recomputed
    source: Mapped[str] = mapped_column(String(16), default="computed", server_default="computed")


class StitchResult(Base):
    """One stitch's placement in a session (SI units), computed with the session's metrics."""

    __tablename__ = "stitch_results"
    __table_args__ = (
        UniqueConstraint("session_id", "stitch", "quantity", "registry_version", name="uq_stitch_result"),
    )
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    session_id: Mapped[int] = mapped_column(ForeignKey("sessions.id", ondelete="CASCADE"), index=True)
    stitch: Mapped[int] = mapped_column(Integer)  # 1, 2, ... in the order the bites were made
    quantity: Mapped[str] = mapped_column(String(32))
    value: Mapped[float | None] = mapped_column(Float, nullable=True)
    registry_version: Mapped[str] = mapped_column(String(16))


class Rating(Base):
    """A rating of a session by a named rater, e.g. OSATS or GRS items and totals."""

    __tablename__ = "ratings"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    session_id: Mapped[int] = mapped_column(ForeignKey("sessions.id", ondelete="CASCADE"), index=True)
    rater: Mapped[str] = mapped_column(String(100))
    instrument: Mapped[str] = mapped_column(String(32))
    item: Mapped[str] = mapped_column(String(100))
    score: Mapped[float] = mapped_column(Float)
    created_at: Mapped[datetime] = mapped_column(DateTime)


class Annotation(Base):
    __tablename__ = "annotations"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    session_id: Mapped[int] = mapped_column(ForeignKey("sessions.id", ondelete="CASCADE"), index=True)
    author: Mapped[str] = mapped_column(String(100))
    time_s: Mapped[float | None] = mapped_column(Float, nullable=True)
    text: Mapped[str] = mapped_column(Text)
    created_at: Mapped[datetime] = mapped_column(DateTime)


class User(Base):
    """A dashboard account. ``password_hash`` is an Argon2id hash; the password itself is never stored."""

    __tablename__ = "users"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    username: Mapped[str] = mapped_column(String(64), unique=True)
    password_hash: Mapped[str] = mapped_column(String(200))
    role: Mapped[str] = mapped_column(String(16))
    active: Mapped[bool] = mapped_column(Boolean, default=True)
    created_at: Mapped[datetime] = mapped_column(DateTime)


class LoginSession(Base):
    """A signed-in browser: the cookie holds a random token, the catalog only its SHA-256."""

    __tablename__ = "login_sessions"
    token_sha256: Mapped[str] = mapped_column(String(64), primary_key=True)
    user_id: Mapped[int] = mapped_column(ForeignKey("users.id", ondelete="CASCADE"), index=True)
    csrf_token: Mapped[str] = mapped_column(String(64))
    created_at: Mapped[datetime] = mapped_column(DateTime)
    expires_at: Mapped[datetime] = mapped_column(DateTime)


class StationToken(Base):
    """A remote station's ingest credential (stored as SHA-256; shown once when created)."""

    __tablename__ = "station_tokens"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    station: Mapped[str] = mapped_column(String(64), unique=True)
    token_sha256: Mapped[str] = mapped_column(String(64), unique=True)
    created_at: Mapped[datetime] = mapped_column(DateTime)
    revoked_at: Mapped[datetime | None] = mapped_column(DateTime, nullable=True)
