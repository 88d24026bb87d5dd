"""A study exported as one archive (:mod:`sessions.exchange.bundle` reads it back, treating it as hostile).

The ZIP holds ``manifest.json`` (the study, its participants, the tasks they used, every session
with its files, metric results, ratings, annotations and kept verdict, and every version of the
study's standards with its re-judging log), ``files/<session uid>/<file name>`` for
each stream file, the manifest's SHA-256 in ``manifest.sha256`` and, with a signing key, its
Ed25519 signature. Every file is copied with its SHA-256 checked against the catalog's.
"""

from __future__ import annotations

import hashlib
import json
import math
import zipfile
from datetime import datetime
from pathlib import Path
from typing import Any

from sessions.catalog import Catalog, CatalogError
from sessions.catalog.lookups import participants_of
from sessions.catalog.models import (
    Session,
    StreamFile,
)
from sessions.catalog.standards import rejudgements_of, standards_of, study_verdicts
from sessions.exchange.manifest import (
    BUNDLE_FORMAT,
    BUNDLE_VERSION,
    CHUNK,
    MANIFEST,
    MANIFEST_CHECKSUM,
    PARTICIPANT_FIELDS,
    SESSION_FIELDS,
)
from sessions.exchange.signing import SIGNATURE, sign
from sessions.status import SessionStatus


def _when(value: datetime | None) -> str | None:
    return None if value is None else value.isoformat()


def _row(obj: Any, fields: tuple[str, ...]) -> dict[str, Any]:
    out = {}
    for name in fields:
        value = getattr(obj, name)
        out[name] = _when(value) if isinstance(value, datetime) else value
    return out


def _standards(orm, study_id: int) -> list[dict[str, Any]]:
    """Every version of the study's standards as it was set, each with the log of re-judgings under
    it; intervals a bootstrap could not give (NaN) travel as null (JSON has no NaN)."""
    rows = standards_of(orm, study_id)
    logs: dict[int, list[dict[str, Any]]] = {}
    for log in rejudgements_of(orm, [r.id for r in rows]):
        logs.setdefault(log.standard_id, []).append(
            {
                "judged_by": log.judged_by,
                "judged_at": _when(log.judged_at),
                "reason": log.reason,
                "sessions": log.sessions,
                "changed": log.changed,
            }
        )
    return [
        {
            "task": row.task,
            "version": row.version,
            "rule": row.rule,
            "marks": [_mark(mark) for mark in row.marks],
            "experts": list(row.experts),
            "sessions": list(row.sessions),
            "min_experts": row.min_experts,
            "registry_version": row.registry_version,
            "analysis_version": row.analysis_version,
            "set_by": row.set_by,
            "set_at": _when(row.set_at),
            "note": row.note,
            "rejudgements": logs.get(row.id, []),
        }
        for row in rows
    ]


def _mark(mark: dict[str, Any]) -> dict[str, Any]:
    if mark.get("interval") is None:
        return {k: v for k, v in mark.items() if k != "interval"}
    return {**mark, "interval": [v if v is not None and math.isfinite(v) else None for v in mark["interval"]]}


def _verdicts(orm, study_id: int) -> dict[int, dict[str, Any]]:
    """Session id -> its kept verdict, naming the standard version that gave it."""
    found = study_verdicts(orm, study_id)
    return {
        verdict.session_id: {
            "standard_version": version,
            "passed": bool(verdict.passed),
            "judged_at": _when(verdict.judged_at),
            "how": verdict.how,
        }
        for verdict, version in found
    }


def _session_files(row: Session) -> list[tuple[StreamFile, Path]]:
    """Each catalogued file of a session with where it is on disk (a directory of files, or
    for imported data such as JIGSAWS, the one file the session's ``directory`` names)."""
    where = Path(row.directory)
    pairs = []
    for record in sorted(row.files, key=lambda f: f.name):
        path = where if where.is_file() and where.name == record.name else where / record.name
        pairs.append((record, path))
    return pairs


def export_study(
    catalog: Catalog, study_name: str, out: str | Path, progress=None, sign_key: str | Path | None = None
) -> dict[str, Any]:
    """Write study ``study_name`` to the archive ``out``; returns a summary (path, sessions, files,
    bytes, signing key). Files are checked against their catalogued SHA-256 as they are copied; a
    file that changed or vanished since it was recorded stops the export with an error naming it.
    ``sign_key``: a site's Ed25519 private key (:mod:`sessions.exchange.signing`) signing the manifest."""
    out = Path(out)
    with catalog.session() as orm:
        study = catalog.study(orm, study_name)
        participants = participants_of(orm, study.id)
        manifest: dict[str, Any] = {
            "format": BUNDLE_FORMAT,
            "version": BUNDLE_VERSION,
            "study": {
                "name": study.name,
                "description": study.description,
                "created_at": _when(study.created_at),
                "groups": list(study.custom_groups or ()),
            },
            "participants": [_row(p, PARTICIPANT_FIELDS) for p in participants],
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
            "standards": _standards(orm, study.id),  # as set, with their re-judgings: they travel
        }
        verdicts = _verdicts(orm, study.id)
        copies: list[tuple[str, Path, str]] = []
        for person in participants:
            for row in sorted(person.sessions, key=lambda s: (s.trial, s.uid)):
                if row.status == SessionStatus.RUNNING:
                    raise CatalogError(
                        f"session {row.uid} of study {study_name!r} is still running; finish or "
                        "recover it before exporting",
                        remedy=("recover", row.uid),
                    )
                manifest["tasks"][row.task.name] = {
                    "scenario": row.task.scenario,
                    "parameters": row.task.parameters,
                }
                where = Path(row.directory)
                entry = _row(row, SESSION_FIELDS)
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
                    verdict=verdicts.get(row.id),
                )
                for record, path in _session_files(row):
                    entry["files"].append(
                        {"name": record.name, "sha256": record.sha256, "bytes": record.bytes}
                    )
                    copies.append((f"files/{row.uid}/{record.name}", path, record.sha256))
                manifest["sessions"].append(entry)
    if not manifest["sessions"]:
        raise CatalogError(f"study {study_name!r} has no sessions to export")
    text = json.dumps(manifest, indent=1, sort_keys=True).encode()
    signature = sign(text, sign_key) if sign_key is not None else None  # a bad key fails before writing
    out.parent.mkdir(parents=True, exist_ok=True)
    partial = out.with_name(out.name + ".partial")
    total = 0
    try:
        with zipfile.ZipFile(partial, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=1) as archive:
            for arcname, path, expected in copies:
                total += _copy_checked(path, archive, arcname, expected)
                if progress is not None:
                    progress(arcname)
            archive.writestr(MANIFEST, text)
            archive.writestr(MANIFEST_CHECKSUM, hashlib.sha256(text).hexdigest() + "\n")
            if signature is not None:
                archive.writestr(SIGNATURE, signature)
        partial.replace(out)
    finally:
        partial.unlink(missing_ok=True)
    return {
        "bundle": str(out),
        "sessions": len(manifest["sessions"]),
        "files": len(copies),
        "bytes": total,
        "signed_by": None if signature is None else json.loads(signature)["key"],
    }


def _copy_checked(path: Path, archive: zipfile.ZipFile, arcname: str, expected: str) -> int:
    if not path.is_file():
        raise CatalogError(
            f"stream file {path} is missing; the catalog lists it (checksum {expected[:12]}...)"
        )
    digest = hashlib.sha256()
    size = 0
    with path.open("rb") as source, archive.open(arcname, "w", force_zip64=True) as target:
        while chunk := source.read(CHUNK):
            digest.update(chunk)
            target.write(chunk)
            size += len(chunk)
    if digest.hexdigest() != expected:
        raise CatalogError(
            f"stream file {path} no longer matches its catalogued SHA-256; it changed after recording"
        )
    return size
