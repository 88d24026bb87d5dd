"""The plain frozen values the catalog store answers with (never ORM rows): what a listing, a page or
a command shows of an account, a station, a study, a participant or a session."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from datetime import datetime
from typing import Any


@dataclass(frozen=True)
class Record:
    def as_dict(self) -> dict[str, Any]:
        """JSON-ready: tuples as lists."""
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}


@dataclass(frozen=True)
class UserRecord(Record):
    """An account as every front-end shows it: linked participants as ids and as STUDY:CODE."""

    id: int
    username: str
    role: str
    active: bool
    created_at: datetime
    participant_ids: tuple[int, ...]
    participants: tuple[str, ...]


@dataclass(frozen=True)
class StationRecord(Record):
    """A station's ingest token as listed (the token itself is shown once, when issued)."""

    id: int
    station: str
    created_at: datetime
    revoked_at: datetime | None


@dataclass(frozen=True)
class SessionRecord(Record):
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
class StudyRecord(Record):
    id: int
    name: str
    description: str


@dataclass(frozen=True)
class StudySummary(Record):
    """A study in a listing: its size, and whether any participant is synthetic."""

    id: int
    name: str
    description: str
    participants: int
    sessions: int
    synthetic: bool


@dataclass(frozen=True)
class ParticipantRecord(Record):
    """A participant in a study's listing, with their session count and when they last practised;
    ``account`` is the linked user name, or None (and always None for a reader who may not see
    accounts)."""

    id: int
    study_id: int
    study: str
    code: str
    level: str
    group: str
    years: float | None
    handedness: str
    synthetic: bool
    sessions: int
    last_session_at: datetime | None
    account: str | None = None


@dataclass(frozen=True)
class FileRecord(Record):
    name: str
    bytes: int
    sha256: str


@dataclass(frozen=True)
class AnnotationRecord(Record):
    time_s: float
    text: str
    author: str | None


@dataclass(frozen=True)
class SessionFacts(Record):
    """Everything the catalog holds of one session: its listing row, where its files are, what went
    wrong, its files with checksums, its current metrics (SI, this registry version) and notes."""

    session: SessionRecord
    study_id: int
    participant_id: int
    group: str
    synthetic: bool
    task_id: int
    clock: str
    directory: str
    error: str | None
    files: tuple[FileRecord, ...]
    metrics: dict[str, float]
    annotations: tuple[AnnotationRecord, ...]
