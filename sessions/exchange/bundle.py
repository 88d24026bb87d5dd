"""A study as one self-contained archive: catalog rows and stream files, with checksums.

``export_study`` (:mod:`sessions.exchange.bundle_export`) writes a ZIP holding ``manifest.json``
(the study, its participants, the tasks they used, and every session with its files, metric
results, ratings and annotations) and ``files/<session uid>/<file name>`` for each stream file. Every file's
SHA-256 is in the manifest and the manifest's own SHA-256 is in ``manifest.sha256``.

A checksum anyone can recompute proves nothing against deliberate edits, so
``import_bundle`` treats the archive as hostile and checks everything before it
touches the catalog or the data directory: the archive opens, the manifest matches
its checksum and, when a trusted key is given, its Ed25519 signature
(:mod:`sessions.exchange.signing`); the manifest is valid against its declared schema
(:mod:`sessions.exchange.manifest`: unknown keys, wrong types, closed enumerations, ids and
account links refused); the archive holds exactly the listed files, each of its
listed size (checked before reading) and SHA-256; the study and session ids are
new; every scorable session's metrics can be recomputed from its streams. Only then
are files moved into ``VASCSIM_HOME/sessions`` and rows added in one transaction; a
failure at that stage removes the moved files again, so a bad bundle changes nothing.
"""

from __future__ import annotations

import hashlib
import math
import shutil
import uuid
import zipfile
from collections import Counter
from datetime import datetime
from pathlib import Path
from typing import Any

from metrics import metrics_of
from metrics.session.registry import REGISTRY_VERSION
from metrics.signals.placement import stitch_table
from recorder import RecorderError
from recorder.json_input import JSONInputError, JSONTooDeep, parse_json
from recorder.layout import HEADER_FILE, read_header
from sessions.catalog import AlreadyExists, Catalog, CatalogError, metric_results
from sessions.catalog.groups import declared_group, group_name
from sessions.catalog.lookups import first_catalogued, study_named
from sessions.catalog.models import (
    AnalysisDeclaration,
    Annotation,
    MetricResult,
    Participant,
    Rating,
    Rejudgement,
    Session,
    Standard,
    StreamFile,
    Study,
    Task,
    Verdict,
)
from sessions.exchange.bundle_export import export_study
from sessions.exchange.manifest import (
    BUNDLE_FORMAT,
    BUNDLE_VERSION,
    CHUNK,
    MANIFEST,
    MANIFEST_CHECKSUM,
    MAX_MANIFEST_BYTES,
    SESSION_FIELDS,
    Manifest,
    parse_manifest,
)
from sessions.exchange.signing import SIGNATURE, trusted_fingerprint
from sessions.exchange.signing import verify as verify_signature
from sessions.running.runner import scored_streams, stitch_results
from sessions.scoring.analysis import settings_from_json
from sessions.status import SCORABLE


def _parse_when(value: str | None) -> datetime | None:
    return None if value is None else datetime.fromisoformat(value)


def _read_member(archive: zipfile.ZipFile, name: str, limit: int, bundle: str | Path) -> bytes | None:
    """A small member's bytes (None when absent), refused above ``limit`` bytes before reading."""
    try:
        info = archive.getinfo(name)
    except KeyError:
        return None
    if info.file_size > limit:
        raise CatalogError(f"bundle {bundle}: {name} is {info.file_size} bytes, over the {limit}-byte limit")
    with archive.open(info) as member:
        data = member.read(limit + 1)
    if len(data) > limit:
        raise CatalogError(f"bundle {bundle}: {name} is larger than its archive entry says")
    return data


def read_manifest(bundle: str | Path, trust: str | Path | None = None) -> Manifest:
    """The verified manifest of a bundle: archive readable, manifest checksum right, signed by the
    trusted key (when ``trust`` names a public key file), and valid against the declared schema."""
    bundle = Path(bundle)
    if not bundle.is_file():
        raise CatalogError(f"bundle {bundle} does not exist")
    try:
        with zipfile.ZipFile(bundle) as archive:
            names = Counter(archive.namelist())
            twice = sorted(name for name, count in names.items() if count > 1)
            if twice:  # zipfile reads the last copy; which one a checker read is anyone's guess
                raise CatalogError(
                    f"bundle {bundle} holds {twice[0]} more than once; a bundle names each file once"
                )
            text = _read_member(archive, MANIFEST, MAX_MANIFEST_BYTES, bundle)
            recorded = _read_member(archive, MANIFEST_CHECKSUM, 1024, bundle)
            signature = _read_member(archive, SIGNATURE, 4096, bundle)
    except (zipfile.BadZipFile, OSError, EOFError) as error:
        raise CatalogError(f"bundle {bundle} is not a readable vascsim study bundle ({error})") from None
    if text is None or recorded is None:
        missing = MANIFEST if text is None else MANIFEST_CHECKSUM
        raise CatalogError(f"bundle {bundle} is not a readable vascsim study bundle (no {missing})")
    if hashlib.sha256(text).hexdigest() != recorded.decode(errors="replace").strip():
        raise CatalogError(f"bundle {bundle} is corrupted: its manifest does not match its checksum")
    if trust is not None:
        verify_signature(text, signature, trust, bundle)
    try:
        found = parse_json(text, "its manifest")
    except JSONTooDeep as error:  # nothing to validate: refused here, in one line
        raise CatalogError(f"bundle {bundle} is not a readable vascsim study bundle ({error})") from None
    except JSONInputError:
        found = None  # the schema check below names what is wrong and where
    stated = (found.get("format"), found.get("version")) if isinstance(found, dict) else None
    if stated is not None and stated != (BUNDLE_FORMAT, BUNDLE_VERSION):
        raise CatalogError(
            f"bundle {bundle} has format {found.get('format')!r} version {found.get('version')!r}; "
            f"this vascsim reads {BUNDLE_FORMAT!r} version {BUNDLE_VERSION}"
        )
    try:
        manifest = parse_manifest(text)
    except ValueError as error:
        raise CatalogError(f"bundle {bundle}: manifest {error}") from None
    _check_analyses(manifest.analyses, bundle)
    return manifest


def verify_bundle(bundle: str | Path, progress=None, trust: str | Path | None = None) -> Manifest:
    """Check the archive against the manifest before anything is extracted: it holds exactly the
    listed files, each of the listed size (within the limits) and SHA-256; returns the manifest."""
    manifest = read_manifest(bundle, trust)
    listed = {
        f"files/{entry.uid}/{record.name}": record for entry in manifest.sessions for record in entry.files
    }
    try:
        with zipfile.ZipFile(bundle) as archive:
            members = {info.filename: info for info in archive.infolist() if not info.is_dir()}
            extra = sorted(set(members) - set(listed) - {MANIFEST, MANIFEST_CHECKSUM, SIGNATURE})
            if extra:
                raise CatalogError(f"bundle {bundle} holds {extra[0]}, which its manifest does not list")
            for arcname, record in listed.items():
                info = members.get(arcname)
                if info is None:
                    raise CatalogError(f"bundle {bundle} is corrupted: {arcname} is missing")
                if info.file_size != record.bytes:
                    raise CatalogError(
                        f"bundle {bundle}: {arcname} is {info.file_size} bytes in the archive; "
                        f"its manifest says {record.bytes}"
                    )
                if _digest(archive, info, record.bytes) != record.sha256:
                    raise CatalogError(f"bundle {bundle} is corrupted: {arcname} does not match its SHA-256")
                if progress is not None:
                    progress(arcname)
    except (zipfile.BadZipFile, OSError, EOFError) as error:
        raise CatalogError(f"bundle {bundle} is corrupted: {error}") from None
    return manifest


def _digest(archive: zipfile.ZipFile, info: zipfile.ZipInfo, size: int) -> str | None:
    """SHA-256 of a member, reading at most ``size`` + 1 bytes (None: it held more than ``size``)."""
    digest, seen = hashlib.sha256(), 0
    with archive.open(info) as member:
        while chunk := member.read(min(CHUNK, size + 1 - seen)):
            seen += len(chunk)
            if seen > size:
                return None
            digest.update(chunk)
    return digest.hexdigest()


def import_bundle(
    catalog: Catalog,
    home: Path,
    bundle: str | Path,
    progress=None,
    trust: str | Path | None = None,
    recompute: bool = True,
) -> dict[str, Any]:
    """Add the bundle's study to the catalog, its stream files under ``home/sessions``.

    Refused, with nothing changed, when the bundle is corrupted or does not match its declared
    schema, when ``trust`` names a public key and the bundle is not signed by it, when a study of
    that name exists, or when any of its session ids is already catalogued. Metric values of the
    current registry version are recomputed from the imported streams (``recompute``); values the
    bundle states that differ are counted and replaced. Without ``recompute`` they are stored as
    imported, unverified, and every analysis of the study says so."""
    manifest = verify_bundle(bundle, progress, trust)
    name = manifest.study.name
    uids = [entry.uid for entry in manifest.sessions]
    with catalog.session() as orm:
        if study_named(orm, name) is not None:
            raise AlreadyExists(f"a study named {name!r} already exists; this bundle was already imported")
        clash = first_catalogued(orm, uids)
        if clash is not None:
            raise AlreadyExists(f"session {clash} from the bundle is already in the catalog")
    staging = home / "sessions" / f".import-{uuid.uuid4().hex[:8]}"
    placed: list[Path] = []
    try:
        _extract(bundle, manifest, staging)
        _check_headers(manifest, staging)
        computed = _recompute(manifest, staging, home, progress) if recompute else {}
        with catalog.session() as orm:
            differing = _add_rows(catalog, orm, manifest, home, computed)
            for uid in uids:
                target = home / "sessions" / uid
                if target.exists():
                    raise CatalogError(f"{target} already exists; move it away and import again")
                (staging / uid).rename(target)
                placed.append(target)
    except BaseException:
        for target in placed:
            shutil.rmtree(target, ignore_errors=True)
        raise
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return {
        "study": name,
        "sessions": len(uids),
        "participants": len(manifest.participants),
        "metrics": "recomputed" if recompute else "imported, unverified",
        "metrics_recomputed_sessions": len(computed),
        "metric_values_differing": differing,
        "signed_by": None if trust is None else trusted_fingerprint(trust),
    }


HEADER_AGREES = (
    ("session_id", "uid"),
    ("task", "task"),
    ("participant_id", "participant"),
    ("device", "device"),
)
"""A recorded session's header.json key -> the manifest entry's field that must say the same: the
header's task picks the tissue model the session is scored with, so a header that contradicts its
manifest would score one task's motion on another's wall."""


def _check_headers(manifest: Manifest, staging: Path) -> None:
    """CatalogError naming the session and the key unless every recorded session's own header
    (those with a header.json: the simulator's) agrees with its manifest entry."""

    for entry in manifest.sessions:
        folder = staging / entry.uid
        if entry.single_file or not (folder / HEADER_FILE).is_file():
            continue  # a bench video's track or a JIGSAWS kinematics file: no header of its own
        try:
            header = read_header(folder)
        except RecorderError as error:
            raise CatalogError(f"session {entry.uid} of the bundle: {error}; nothing was imported") from None
        for key, field in HEADER_AGREES:
            if key in header and header[key] != getattr(entry, field):
                raise CatalogError(
                    f"session {entry.uid} of the bundle: its {HEADER_FILE} says {key} {header[key]!r} but "
                    f"the manifest says {getattr(entry, field)!r}; nothing was imported"
                )


def _recompute(manifest: Manifest, staging: Path, home: Path, progress=None) -> dict[str, tuple]:
    """Every scorable session's metrics and per-stitch placement computed from its extracted streams;
    an error names the session."""

    labels = {p.code: p.group_label for p in manifest.participants}
    computed = {}
    for entry in manifest.sessions:
        if entry.status not in SCORABLE:
            continue
        folder = staging / entry.uid
        where = folder / entry.files[0].name if entry.single_file else folder
        try:
            streams = scored_streams(
                where, entry.device, entry.uid, entry.participant, labels[entry.participant], home
            )
            computed[entry.uid] = (metrics_of(streams), stitch_table(streams))
        except Exception as error:  # hostile streams: any failure refuses the whole bundle
            raise CatalogError(
                f"session {entry.uid} of the bundle cannot be scored from its streams "
                f"({type(error).__name__}: {error}); nothing was imported"
            ) from None
        if progress is not None:
            progress(f"scored {entry.uid}")
    return computed


def _check_analyses(entries: Any, bundle: str | Path) -> None:
    """Every declared analysis version of a bundle, checked as a declaration made here would be."""

    if not isinstance(entries, list):
        raise CatalogError(f"bundle {bundle}: 'analyses' must be a list of declared versions")
    versions = []
    for k, entry in enumerate(entries):
        what = f"bundle {bundle}: analyses[{k}]"
        if not isinstance(entry, dict) or set(entry) != {
            "version",
            "settings",
            "author",
            "note",
            "created_at",
        }:
            raise CatalogError(f"{what} must hold exactly version, settings, author, note and created_at")
        if (
            not isinstance(entry["version"], int)
            or isinstance(entry["version"], bool)
            or entry["version"] < 1
        ):
            raise CatalogError(f"{what}: version must be a whole number >= 1; got {entry['version']!r}")
        if not isinstance(entry["author"], str) or not isinstance(entry["note"], str):
            raise CatalogError(f"{what}: author and note must be texts")
        try:
            datetime.fromisoformat(entry["created_at"])
        except (TypeError, ValueError):
            raise CatalogError(f"{what}: created_at {entry['created_at']!r} is not an ISO time") from None
        settings_from_json(entry["settings"], what)
        versions.append(entry["version"])
    if versions != list(range(1, len(versions) + 1)):
        raise CatalogError(f"bundle {bundle}: analysis versions must run 1, 2, ...; got {versions}")


def _extract(bundle: str | Path, manifest: Manifest, staging: Path) -> None:
    with zipfile.ZipFile(bundle) as archive:
        for entry in manifest.sessions:
            folder = staging / entry.uid
            folder.mkdir(parents=True)
            for record in entry.files:
                with (
                    archive.open(f"files/{entry.uid}/{record.name}") as member,
                    (folder / record.name).open("wb") as target,
                ):
                    shutil.copyfileobj(member, target, CHUNK)


def _add_rows(catalog: Catalog, orm, manifest: Manifest, home: Path, computed: dict[str, tuple]) -> int:
    """The bundle's rows; returns how many stated metric values differ from the recomputed ones.

    Participants come without any account link (accounts are this site's business); database ids
    are this catalog's own."""

    info = manifest.study
    custom = [declared_group(name) for name in info.groups]
    study = Study(
        name=info.name, description=info.description, created_at=info.created_at, custom_groups=custom
    )
    orm.add(study)
    orm.flush()
    for entry in manifest.analyses:
        declared = dict(entry, created_at=_parse_when(entry["created_at"]))
        orm.add(AnalysisDeclaration(study_id=study.id, **declared))
    tasks: dict[str, Task] = {}
    for task_name, task_info in manifest.tasks.items():
        task = catalog.task(orm, task_name, task_info.scenario, task_info.parameters)
        if task.scenario != task_info.scenario or task.parameters != task_info.parameters:
            raise CatalogError(
                f"task {task_name!r} in this catalog differs from the bundle's (scenario or parameters); "
                "its sessions would not be comparable"
            )
        tasks[task_name] = task
    people: dict[str, Participant] = {}
    for person in manifest.participants:
        fields = person.model_dump()
        what = f"the bundle's participant {person.code!r}"
        fields["level"] = group_name(person.level, custom, f"level of {what}", info.name)
        fields["group_label"] = group_name(person.group_label, custom, f"group of {what}", info.name)
        people[person.code] = Participant(study_id=study.id, **fields)
        orm.add(people[person.code])
    orm.flush()
    differing = 0
    sessions: dict[str, Session] = {}
    for entry in manifest.sessions:
        folder = home / "sessions" / entry.uid
        directory = folder / entry.files[0].name if entry.single_file else folder
        session = Session(
            participant_id=people[entry.participant].id,
            task_id=tasks[entry.task].id,
            directory=str(directory),
            **entry.model_dump(include=set(SESSION_FIELDS)),
        )
        orm.add(session)
        orm.flush()
        orm.add_all(StreamFile(session_id=session.id, **record.model_dump()) for record in entry.files)
        fresh, stitches = computed.get(entry.uid, (None, None))
        stated = [m for m in entry.metrics if fresh is None or m.registry_version != REGISTRY_VERSION]
        orm.add_all(MetricResult(session_id=session.id, source="imported", **m.model_dump()) for m in stated)
        if fresh is not None:
            orm.add_all(metric_results(session.id, fresh))
            orm.add_all(stitch_results(session.id, stitches))
            differing += _count_differing(entry, fresh, REGISTRY_VERSION)
        orm.add_all(Rating(session_id=session.id, **r.model_dump()) for r in entry.ratings)
        orm.add_all(Annotation(session_id=session.id, **a.model_dump()) for a in entry.annotations)
        sessions[entry.uid] = session
    _add_standards(orm, study, manifest, sessions)
    orm.flush()
    return differing


def _add_standards(orm, study: Study, manifest: Manifest, sessions: dict[str, Session]) -> None:
    """The bundle's standards as they were set, their re-judgings, and each session's kept verdict
    under the version that gave it: a study keeps its standing decisions when it moves site."""
    ids: dict[tuple[str, int], int] = {}
    for entry in manifest.standards:
        fields = entry.model_dump(exclude={"marks", "rejudgements"})
        marks = [
            {k: v for k, v in mark.model_dump().items() if k != "interval" or v is not None}
            for mark in entry.marks
        ]
        row = Standard(study_id=study.id, marks=marks, **fields)
        orm.add(row)
        orm.flush()
        ids[(entry.task, entry.version)] = row.id
        orm.add_all(Rejudgement(standard_id=row.id, **log.model_dump()) for log in entry.rejudgements)
    for entry in manifest.sessions:
        if entry.verdict is not None:
            verdict = entry.verdict.model_dump()
            standard = ids[(entry.task, verdict.pop("standard_version"))]
            orm.add(Verdict(session_id=sessions[entry.uid].id, standard_id=standard, **verdict))


def _count_differing(entry, fresh: dict[str, float], version: str) -> int:
    """Stated values of ``version`` that the recomputation does not reproduce (NaN equals NULL)."""
    count = 0
    for metric in entry.metrics:
        if metric.registry_version != version:
            continue
        value = fresh.get(metric.metric, float("nan"))
        same = (metric.value is None and math.isnan(value)) or (
            metric.value is not None and math.isclose(metric.value, value, rel_tol=1e-9, abs_tol=1e-12)
        )
        count += not same
    return count


__all__ = ["export_study", "import_bundle", "read_manifest", "verify_bundle"]
