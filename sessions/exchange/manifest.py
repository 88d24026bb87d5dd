"""The declared schema of a study bundle's manifest (format ``vascsim-study-bundle``, version 1).

A manifest arrives from outside: anyone can edit it and recompute its checksum. So it is
validated completely before anything is stored: unknown keys are refused at every level,
every field has its type (no string where a number belongs, no bool where an integer does),
enumerations are closed (a session is complete, recovered or failed; never running), times
are ISO times, numbers are finite, names are plain file names, and references between parts
(a session's participant and task) resolve. Database ids and account links are not part of
the format: accounts belong to the importing site.
"""

from __future__ import annotations

import math
import re
from datetime import UTC, datetime
from typing import Annotated, Any, Literal

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, ValidationError, model_validator

BUNDLE_FORMAT = "vascsim-study-bundle"
BUNDLE_VERSION = 1
MAX_MEMBER_BYTES = 8 * 2**30
"""Largest stream file a bundle may hold (a one-hour 1 kHz session is well under 1 GiB)."""
MAX_BUNDLE_BYTES = 256 * 2**30
"""Largest total of a bundle's stream files."""
MANIFEST = "manifest.json"
MANIFEST_CHECKSUM = "manifest.sha256"
CHUNK = 1 << 20
"""Bytes copied at a time between an archive and a file."""
PARTICIPANT_FIELDS = (
    "code",
    "level",
    "years_experience",
    "handedness",
    "group_label",
    "synthetic",
    "created_at",
)
SESSION_FIELDS = ("uid", "device", "clock", "trial", "phase", "status", "started_at", "ended_at", "error")
"""The catalog columns a bundle carries for each participant and session, by name."""
MAX_MANIFEST_BYTES = 64 * 2**20

_PLAIN_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,199}$")


def _plain(name: str) -> str:
    if not _PLAIN_NAME.match(name):  # no paths: nothing can leave the data directory
        raise ValueError(f"names a file or session {name!r} that is not a plain name")
    return name


def _finite(value: float | None) -> float | None:
    if value is not None and not math.isfinite(value):
        raise ValueError("must be a finite number")
    return value


def _naive_utc(value: datetime) -> datetime:
    """The catalog stores UTC without a zone: a stated zone is converted, none is taken as UTC."""
    return value if value.tzinfo is None else value.astimezone(UTC).replace(tzinfo=None)


When = Annotated[datetime, AfterValidator(_naive_utc)]
PlainName = Annotated[str, AfterValidator(_plain)]
Finite = Annotated[float, AfterValidator(_finite)]
OptionalFinite = Annotated[float | None, AfterValidator(_finite)]
Text = Annotated[str, Field(max_length=10_000)]


def _label(length: int) -> Any:
    return Annotated[str, Field(max_length=length)]


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True, frozen=True)


class StudyRecord(_Strict):
    name: Annotated[str, Field(min_length=1, max_length=200)]
    description: Text
    created_at: When
    # groups the study declared beyond the standard ones (sessions.catalog.groups); older bundles: none
    groups: Annotated[list[_label(32)], Field(max_length=50)] = []


class ParticipantRecord(_Strict):
    code: Annotated[str, Field(min_length=1, max_length=64)]
    level: _label(32)
    years_experience: Annotated[Finite, Field(ge=0, le=80)] | None = None
    handedness: Literal["right", "left", "ambidextrous"]
    group_label: _label(64)
    synthetic: bool
    created_at: When


class TaskRecord(_Strict):
    scenario: Annotated[str, Field(min_length=1, max_length=100)]
    parameters: dict[str, Any]


class FileRecord(_Strict):
    name: PlainName
    sha256: Annotated[str, Field(pattern=r"^[0-9a-f]{64}$")]
    bytes: Annotated[int, Field(ge=0, le=MAX_MEMBER_BYTES)]


class MetricRecord(_Strict):
    metric: Annotated[str, Field(min_length=1, max_length=100)]
    value: OptionalFinite
    registry_version: Annotated[str, Field(min_length=1, max_length=16)]


class RatingRecord(_Strict):
    rater: Annotated[str, Field(min_length=1, max_length=100)]
    instrument: Annotated[str, Field(min_length=1, max_length=32)]
    item: Annotated[str, Field(min_length=1, max_length=100)]
    score: Finite
    created_at: When


class AnnotationRecord(_Strict):
    author: _label(100)
    time_s: Annotated[Finite, Field(ge=0)] | None = None
    text: Text
    created_at: When


class VerdictRecord(_Strict):
    """A session's kept verdict (sessions.scoring.verdicts): under which version of its task's standard."""

    standard_version: Annotated[int, Field(ge=1, le=1_000_000)]
    passed: bool
    judged_at: When
    how: _label(300)


class MarkRecord(_Strict):
    metric: Annotated[str, Field(min_length=1, max_length=100)]
    benchmark: Finite
    better: Literal["lower", "higher"]
    pass_if: _label(100)
    experts: Annotated[int, Field(ge=0, le=1_000_000)]
    interval: Annotated[list[OptionalFinite], Field(min_length=2, max_length=2)] | None = None


class RejudgementRecord(_Strict):
    judged_by: _label(100)
    judged_at: When
    reason: Text
    sessions: Annotated[int, Field(ge=0, le=100_000_000)]
    changed: Annotated[int, Field(ge=0, le=100_000_000)]


class StandardRecordModel(_Strict):
    """One version of the study's standard on a task, as it was set (sessions.scoring.standards), with the
    log of re-judgings under it."""

    task: Annotated[str, Field(min_length=1, max_length=100)]
    version: Annotated[int, Field(ge=1, le=1_000_000)]
    rule: Annotated[str, Field(min_length=1, max_length=32)]
    marks: Annotated[list[MarkRecord], Field(min_length=1, max_length=500)]
    experts: list[Annotated[str, Field(min_length=1, max_length=64)]]
    sessions: list[PlainName]
    min_experts: Annotated[int, Field(ge=1, le=100_000)]
    registry_version: Annotated[str, Field(min_length=1, max_length=16)]
    analysis_version: Annotated[int, Field(ge=1, le=1_000_000)] | None
    set_by: _label(100)
    set_at: When
    note: Text
    rejudgements: list[RejudgementRecord] = []

    @model_validator(mode="after")
    def _consistent(self) -> StandardRecordModel:
        names = [m.metric for m in self.marks]
        if len(set(names)) != len(names):
            raise ValueError(f"standard v{self.version} on {self.task} marks {_first_repeat(names)!r} twice")
        return self


class SessionRecord(_Strict):
    uid: PlainName
    participant: Annotated[str, Field(min_length=1, max_length=64)]
    task: Annotated[str, Field(min_length=1, max_length=100)]
    device: Annotated[str, Field(min_length=1, max_length=100)]
    clock: Literal["simulated", "realtime", "recorded"]
    trial: Annotated[int, Field(ge=1, le=1_000_000)]
    phase: Literal["practice", "retention"]
    status: Literal["complete", "recovered", "failed"]
    started_at: When
    ended_at: When | None
    error: Text
    single_file: bool
    files: Annotated[list[FileRecord], Field(min_length=1)]
    metrics: list[MetricRecord]
    ratings: list[RatingRecord]
    annotations: list[AnnotationRecord]
    verdict: VerdictRecord | None = None  # bundles before standards travelled have none

    @model_validator(mode="after")
    def _consistent(self) -> SessionRecord:
        names = [record.name for record in self.files]
        if len(set(names)) != len(names):
            raise ValueError(f"session {self.uid} lists a file twice")
        if self.single_file and len(names) != 1:
            raise ValueError(f"session {self.uid} is a single-file session with {len(names)} files")
        keys = [(m.metric, m.registry_version) for m in self.metrics]
        if len(set(keys)) != len(keys):
            raise ValueError(f"session {self.uid} lists a metric twice for one registry version")
        return self


class Manifest(_Strict):
    format: Literal["vascsim-study-bundle"]
    version: Literal[1]
    study: StudyRecord
    participants: list[ParticipantRecord]
    analyses: Any  # checked by sessions.scoring.analysis's own declaration rules (sessions.exchange.bundle)
    tasks: dict[Annotated[str, Field(min_length=1, max_length=100)], TaskRecord]
    sessions: Annotated[list[SessionRecord], Field(min_length=1)]
    standards: list[StandardRecordModel] = []  # bundles before standards travelled have none

    @model_validator(mode="after")
    def _references(self) -> Manifest:
        codes = [p.code for p in self.participants]
        if len(set(codes)) != len(codes):
            raise ValueError(f"participant {_first_repeat(codes)!r} is listed twice")
        uids = [s.uid for s in self.sessions]
        if len(set(uids)) != len(uids):
            raise ValueError(f"session {_first_repeat(uids)!r} is listed twice")
        trials = [(s.participant, s.task, s.trial) for s in self.sessions]
        if len(set(trials)) != len(trials):
            participant, task, trial = _first_repeat(trials)
            raise ValueError(f"participant {participant!r} has trial {trial} of task {task!r} twice")
        for session in self.sessions:
            if session.participant not in codes:
                raise ValueError(f"session {session.uid} names unknown participant {session.participant!r}")
            if session.task not in self.tasks:
                raise ValueError(f"session {session.uid} names unknown task {session.task!r}")
        self._standards_resolve(set(codes), set(uids))
        total = sum(f.bytes for s in self.sessions for f in s.files)
        if total > MAX_BUNDLE_BYTES:
            raise ValueError(f"its files add up to {total} bytes, over the {MAX_BUNDLE_BYTES}-byte limit")
        return self

    def _standards_resolve(self, codes: set[str], uids: set[str]) -> None:
        """Each standard's task, experts and sessions are the bundle's own; each version is listed
        once; each session's verdict names a version of its own task's standard."""
        versions = [(s.task, s.version) for s in self.standards]
        if len(set(versions)) != len(versions):
            task, version = _first_repeat(versions)
            raise ValueError(f"standard v{version} on {task!r} is listed twice")
        for standard in self.standards:
            what = f"standard v{standard.version} on {standard.task!r}"
            if standard.task not in self.tasks:
                raise ValueError(f"{what} is on a task the bundle does not have")
            stranger = next((c for c in standard.experts if c not in codes), None)
            if stranger is not None:
                raise ValueError(f"{what} names expert {stranger!r}, who is not in the bundle")
            unknown = next((u for u in standard.sessions if u not in uids), None)
            if unknown is not None:
                raise ValueError(f"{what} names session {unknown!r}, which is not in the bundle")
        known = set(versions)
        for session in self.sessions:
            verdict = session.verdict
            if verdict is not None and (session.task, verdict.standard_version) not in known:
                raise ValueError(
                    f"session {session.uid}'s verdict names standard v{verdict.standard_version} on "
                    f"{session.task!r}, which the bundle does not have"
                )


def _first_repeat(items: list) -> Any:
    seen = set()
    for item in items:
        if item in seen:
            return item
        seen.add(item)
    return None


def parse_manifest(text: bytes) -> Manifest:
    """The manifest, validated against the schema; ValueError with one line naming the first
    problem and where it is (``sessions[2].trial: Input should be a valid integer``)."""
    try:
        return Manifest.model_validate_json(text, strict=True)
    except ValidationError as error:
        first = error.errors()[0]
        where = "".join(f"[{part}]" if isinstance(part, int) else f".{part}" for part in first["loc"])
        message = first["msg"].removeprefix("Value error, ")
        count = error.error_count()
        more = f" (and {count - 1} more problem{'s' if count > 2 else ''})" if count > 1 else ""
        raise ValueError(f"{where.lstrip('.') or 'the manifest'}: {message}{more}") from None
