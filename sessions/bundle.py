"""A study as one self-contained archive: catalog rows and stream files, with checksums.

``export_study`` writes a ZIP holding ``manifest.json`` (the study, its participants, the
tasks they used, and every session with its files, metric results, ratings and
annotations) and ``files/<session uid>/<file name>`` for each stream file. Every file's
SHA-256 is in the manifest and the manifest's own SHA-256 is in ``manifest.sha256``.

``import_bundle`` checks everything before it touches the catalog or the data
directory: the archive opens, the manifest's checksum matches, every file's checksum
matches, the study and session ids are not already present. Only then are files
copied into ``VASCSIM_HOME/sessions`` and rows added in one transaction; a failure at
that stage removes the copied files again, so a bad bundle changes nothing.
"""

from __future__ import annotations

import hashlib
import json
import re
import shutil
import uuid
import zipfile
from datetime import datetime
from pathlib import Path
from typing import Any

from sqlalchemy import select

from sessions.catalog import Catalog, CatalogError
from sessions.models import (
    AnalysisDeclaration,
    Annotation,
    MetricResult,
    Participant,
    Rating,
    Session,
    StreamFile,
    Study,
    Task,
)

BUNDLE_FORMAT = "vascsim-study-bundle"
BUNDLE_VERSION = 1
MANIFEST = "manifest.json"
MANIFEST_CHECKSUM = "manifest.sha256"
_CHUNK = 1 << 20
_SAFE_NAME = re.compile(
    r"^[A-Za-z0-9][A-Za-z0-9._-]{0,199}$"
)  # no paths: nothing can leave the data directory

_PARTICIPANT_FIELDS = (
    "code",
    "level",
    "years_experience",
    "handedness",
    "group_label",
    "synthetic",
    "created_at",
)
_SESSION_FIELDS = ("uid", "device", "clock", "trial", "phase", "status", "started_at", "ended_at", "error")


def _when(value: datetime | None) -> str | None:
    return None if value is None else value.isoformat()


def _parse_when(value: str | None) -> datetime | None:
    return None if value is None else datetime.fromisoformat(value)


def _row(obj: Any, fields: tuple[str, ...]) -> dict[str, Any]:
    out = {}
    for name in fields:
        value = getattr(obj, name)
        out[name] = _when(value) if isinstance(value, datetime) else value
    return out


def _session_files(row: Session) -> list[tuple[StreamFile, Path]]:
    """Each catalogued file of a session with where it is on disk (a directory of files, or
    for imported data such as JIGSAWS, the one file the session's ``directory`` names)."""
    where = Path(row.directory)
    pairs = []
    for record in sorted(row.files, key=lambda f: f.name):
        path = where if where.is_file() and where.name == record.name else where / record.name
        pairs.append((record, path))
    return pairs


def export_study(catalog: Catalog, study_name: str, out: str | Path, progress=None) -> dict[str, Any]:
    """Write study ``study_name`` to the archive ``out``; returns a summary (path, sessions, files,
    bytes). Files are checked against their catalogued SHA-256 as they are copied; a file that
    changed or vanished since it was recorded stops the export with an error naming it."""
    out = Path(out)
    with catalog.session() as orm:
        study = catalog.study(orm, study_name)
        participants = list(
            orm.scalars(
                select(Participant).where(Participant.study_id == study.id).order_by(Participant.code)
            )
        )
        manifest: dict[str, Any] = {
            "format": BUNDLE_FORMAT,
            "version": BUNDLE_VERSION,
            "study": {
                "name": study.name,
                "description": study.description,
                "created_at": _when(study.created_at),
            },
            "participants": [_row(p, _PARTICIPANT_FIELDS) for p in participants],
            # the study's declared analysis, every version, so an import analyses it the same way
            "analyses": [
                {
                    "version": d.version,
                    "settings": d.settings,
                    "author": d.author,
                    "note": d.note,
                    "created_at": _when(d.created_at),
                }
                for d in study.analyses
            ],
            "tasks": {},
            "sessions": [],
        }
        copies: list[tuple[str, Path, str]] = []
        for person in participants:
            for row in sorted(person.sessions, key=lambda s: (s.trial, s.uid)):
                if row.status == "running":
                    raise CatalogError(
                        f"session {row.uid} of study {study_name!r} is still running; finish it or "
                        f"`vascsim recover {row.uid}` before exporting"
                    )
                manifest["tasks"][row.task.name] = {
                    "scenario": row.task.scenario,
                    "parameters": row.task.parameters,
                }
                where = Path(row.directory)
                entry = _row(row, _SESSION_FIELDS)
                entry.update(
                    participant=person.code,
                    task=row.task.name,
                    single_file=where.is_file(),
                    files=[],
                    metrics=[
                        {"metric": m.metric, "value": m.value, "registry_version": m.registry_version}
                        for m in sorted(row.metrics, key=lambda m: (m.registry_version, m.metric))
                    ],
                    ratings=[
                        {
                            "rater": r.rater,
                            "instrument": r.instrument,
                            "item": r.item,
                            "score": r.score,
                            "created_at": _when(r.created_at),
                        }
                        for r in row.ratings
                    ],
                    annotations=[
                        {
                            "author": a.author,
                            "time_s": a.time_s,
                            "text": a.text,
                            "created_at": _when(a.created_at),
                        }
                        for a in row.annotations
                    ],
                )
                for record, path in _session_files(row):
                    entry["files"].append(
                        {"name": record.name, "sha256": record.sha256, "bytes": record.bytes}
                    )
                    copies.append((f"files/{row.uid}/{record.name}", path, record.sha256))
                manifest["sessions"].append(entry)
    if not manifest["sessions"]:
        raise CatalogError(f"study {study_name!r} has no sessions to export")
    out.parent.mkdir(parents=True, exist_ok=True)
    partial = out.with_name(out.name + ".partial")
    total = 0
    try:
        with zipfile.ZipFile(partial, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=1) as archive:
            for arcname, path, expected in copies:
                total += _copy_checked(path, archive, arcname, expected)
                if progress is not None:
                    progress(arcname)
            text = json.dumps(manifest, indent=1, sort_keys=True).encode()
            archive.writestr(MANIFEST, text)
            archive.writestr(MANIFEST_CHECKSUM, hashlib.sha256(text).hexdigest() + "\n")
        partial.replace(out)
    finally:
        partial.unlink(missing_ok=True)
    return {"bundle": str(out), "sessions": len(manifest["sessions"]), "files": len(copies), "bytes": total}


def _copy_checked(path: Path, archive: zipfile.ZipFile, arcname: str, expected: str) -> int:
    if not path.is_file():
        raise CatalogError(
            f"stream file {path} is missing; the catalog lists it (checksum {expected[:12]}...)"
        )
    digest = hashlib.sha256()
    size = 0
    with path.open("rb") as source, archive.open(arcname, "w", force_zip64=True) as target:
        while chunk := source.read(_CHUNK):
            digest.update(chunk)
            target.write(chunk)
            size += len(chunk)
    if digest.hexdigest() != expected:
        raise CatalogError(
            f"stream file {path} no longer matches its catalogued SHA-256; it changed after recording"
        )
    return size


def read_manifest(bundle: str | Path) -> dict[str, Any]:
    """The verified manifest of a bundle (archive readable, manifest checksum and format right)."""
    bundle = Path(bundle)
    if not bundle.is_file():
        raise CatalogError(f"bundle {bundle} does not exist")
    try:
        with zipfile.ZipFile(bundle) as archive:
            text = archive.read(MANIFEST)
            recorded = archive.read(MANIFEST_CHECKSUM).decode().strip()
    except (zipfile.BadZipFile, KeyError, OSError, EOFError) as error:
        raise CatalogError(f"bundle {bundle} is not a readable vascsim study bundle ({error})") from None
    if hashlib.sha256(text).hexdigest() != recorded:
        raise CatalogError(f"bundle {bundle} is corrupted: its manifest does not match its checksum")
    manifest = json.loads(text)
    if manifest.get("format") != BUNDLE_FORMAT or manifest.get("version") != BUNDLE_VERSION:
        raise CatalogError(
            f"bundle {bundle} has format {manifest.get('format')!r} version {manifest.get('version')!r}; "
            f"this vascsim reads {BUNDLE_FORMAT!r} version {BUNDLE_VERSION}"
        )
    for entry in manifest.get("sessions", []):
        names = [entry.get("uid", ""), *(record.get("name", "") for record in entry.get("files", []))]
        for name in names:
            if not isinstance(name, str) or not _SAFE_NAME.match(name):
                raise CatalogError(
                    f"bundle {bundle} names a file or session {name!r} that is not a plain name"
                )
    return manifest


def verify_bundle(bundle: str | Path, progress=None) -> dict[str, Any]:
    """Read every file of the bundle and check it against the manifest; returns the manifest."""
    manifest = read_manifest(bundle)
    try:
        with zipfile.ZipFile(bundle) as archive:
            for entry in manifest["sessions"]:
                for record in entry["files"]:
                    arcname = f"files/{entry['uid']}/{record['name']}"
                    digest = hashlib.sha256()
                    with archive.open(arcname) as member:
                        while chunk := member.read(_CHUNK):
                            digest.update(chunk)
                    if digest.hexdigest() != record["sha256"]:
                        raise CatalogError(
                            f"bundle {bundle} is corrupted: {arcname} does not match its SHA-256"
                        )
                    if progress is not None:
                        progress(arcname)
    except (zipfile.BadZipFile, KeyError, OSError, EOFError) as error:
        raise CatalogError(f"bundle {bundle} is corrupted: {error}") from None
    return manifest


def import_bundle(catalog: Catalog, home: Path, bundle: str | Path, progress=None) -> dict[str, Any]:
    """Add the bundle's study to the catalog, its stream files under ``home/sessions``.

    Refused, with nothing changed, when the bundle is corrupted, when a study of that name
    exists, or when any of its session ids is already catalogued."""
    manifest = verify_bundle(bundle, progress)
    _check_analyses(manifest.get("analyses", []), bundle)
    name = manifest["study"]["name"]
    uids = [entry["uid"] for entry in manifest["sessions"]]
    with catalog.session() as orm:
        if orm.scalar(select(Study).where(Study.name == name)) is not None:
            raise CatalogError(f"a study named {name!r} already exists; this bundle was already imported")
        clash = orm.scalar(select(Session.uid).where(Session.uid.in_(uids)))
        if clash is not None:
            raise CatalogError(f"session {clash} from the bundle is already in the catalog")
    staging = home / "sessions" / f".import-{uuid.uuid4().hex[:8]}"
    placed: list[Path] = []
    try:
        _extract(bundle, manifest, staging)
        with catalog.session() as orm:
            _add_rows(catalog, orm, manifest, home)
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
    return {"study": name, "sessions": len(uids), "participants": len(manifest["participants"])}


def _check_analyses(entries: Any, bundle: str | Path) -> None:
    """Every declared analysis version of a bundle, checked as a declaration made here would be."""
    from sessions.analysis import settings_from_json

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


def _extract(bundle: str | Path, manifest: dict[str, Any], staging: Path) -> None:
    with zipfile.ZipFile(bundle) as archive:
        for entry in manifest["sessions"]:
            folder = staging / entry["uid"]
            folder.mkdir(parents=True)
            for record in entry["files"]:
                with (
                    archive.open(f"files/{entry['uid']}/{record['name']}") as member,
                    (folder / Path(record["name"]).name).open("wb") as target,
                ):
                    shutil.copyfileobj(member, target, _CHUNK)


def _add_rows(catalog: Catalog, orm, manifest: dict[str, Any], home: Path) -> None:
    info = manifest["study"]
    study = Study(
        name=info["name"], description=info["description"], created_at=_parse_when(info["created_at"])
    )
    orm.add(study)
    orm.flush()
    for entry in manifest.get("analyses", []):
        orm.add(
            AnalysisDeclaration(study_id=study.id, **dict(entry, created_at=_parse_when(entry["created_at"])))
        )
    tasks: dict[str, Task] = {}
    for task_name, task_info in manifest["tasks"].items():
        task = catalog.task(orm, task_name, task_info["scenario"], task_info["parameters"])
        if task.scenario != task_info["scenario"] or task.parameters != task_info["parameters"]:
            raise CatalogError(
                f"task {task_name!r} in this catalog differs from the bundle's (scenario or parameters); "
                "its sessions would not be comparable"
            )
        tasks[task_name] = task
    people: dict[str, Participant] = {}
    for person in manifest["participants"]:
        fields = dict(person, created_at=_parse_when(person["created_at"]))
        people[person["code"]] = Participant(study_id=study.id, **fields)
        orm.add(people[person["code"]])
    orm.flush()
    for entry in manifest["sessions"]:
        folder = home / "sessions" / entry["uid"]
        directory = folder / entry["files"][0]["name"] if entry["single_file"] else folder
        session = Session(
            participant_id=people[entry["participant"]].id,
            task_id=tasks[entry["task"]].id,
            directory=str(directory),
            **{
                key: _parse_when(entry[key]) if key in ("started_at", "ended_at") else entry[key]
                for key in _SESSION_FIELDS
            },
        )
        orm.add(session)
        orm.flush()
        orm.add_all(StreamFile(session_id=session.id, **record) for record in entry["files"])
        orm.add_all(MetricResult(session_id=session.id, **m) for m in entry["metrics"])
        orm.add_all(
            Rating(session_id=session.id, **dict(r, created_at=_parse_when(r["created_at"])))
            for r in entry["ratings"]
        )
        orm.add_all(
            Annotation(session_id=session.id, **dict(a, created_at=_parse_when(a["created_at"])))
            for a in entry["annotations"]
        )
    orm.flush()
