"""A session directory's layout: its file names, the header, checksums and checked reads.

Every module that writes or reads a session (writer, reader, scene, ingest, station) and every
front-end that looks into one takes the names from here:

- ``header.json``: what the session is, and a record (file, rows, SHA-256) of each stream file;
- ``samples.arrows`` / ``events.arrows``: the append-only journals while recording;
- ``samples.parquet`` / ``events.parquet`` / ``scene.parquet``: the verified streams once closed.

A stream file is trusted only after :func:`read_checked` has compared it with its header record
(checksum, row count) and its schema.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from recorder.json_input import JSONInputError, parse_json
from recorder.schema import RecorderError

HEADER_FILE = "header.json"
SAMPLES_JOURNAL, EVENTS_JOURNAL = "samples.arrows", "events.arrows"
SAMPLES_FILE, EVENTS_FILE, SCENE_FILE = "samples.parquet", "events.parquet", "scene.parquet"


def sha256_of(path: Path) -> str:
    """SHA-256 (hex) of a file's bytes, read in 1 MiB chunks."""
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for chunk in iter(lambda: handle.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()


def write_json_atomically(path: Path, data: dict[str, Any]) -> None:
    """Write JSON (no NaN) to a temporary file, fsync it and rename it over ``path``."""
    temporary = path.with_suffix(path.suffix + ".tmp")
    with open(temporary, "w") as handle:
        json.dump(data, handle, indent=2, sort_keys=True, allow_nan=False)  # NaN is not JSON
        handle.flush()
        os.fsync(handle.fileno())
    os.replace(temporary, path)


def read_header(directory: Path) -> dict[str, Any]:
    """A session directory's ``header.json``; RecorderError if it is missing, damaged or not an object."""

    path = directory / HEADER_FILE
    try:
        header = parse_json(path.read_bytes(), str(path))  # a bundle's or a station's: outside input
    except FileNotFoundError:
        raise RecorderError(f"{directory} is not a session directory (no {HEADER_FILE})") from None
    except JSONInputError as error:
        raise RecorderError(f"{error} (damaged?)") from None
    if not isinstance(header, dict):
        raise RecorderError(f"{path} holds a JSON {type(header).__name__}, not a session header object")
    return header


def is_session_directory(directory: Path) -> bool:
    return (Path(directory) / HEADER_FILE).is_file()


def read_checked(path: Path, name: str, record: Any, verify: bool, schema: pa.Schema) -> pa.Table:
    """The stream file ``name`` of session directory ``path``, checked against its header ``record``
    (its SHA-256 when ``verify``, its row count) and ``schema``; RecorderError naming what is wrong."""
    file = path / name
    if not isinstance(record, dict):
        raise RecorderError(f"{path / HEADER_FILE} does not describe {name} (no file record in the header)")
    if not file.is_file():
        raise RecorderError(f"{file} is missing")
    if verify:
        expected = record.get("sha256")
        if expected is None:
            raise RecorderError(f"{path / HEADER_FILE} records no checksum for {name}")
        if sha256_of(file) != expected:
            raise RecorderError(f"{file} does not match its recorded SHA-256 (corrupted or altered)")
    try:
        table = pq.read_table(file)
        # a damaged footer can still parse with a column name that is not UTF-8 (unverified reads)
        found = {field.name: field.type for field in table.schema}
    except (pa.ArrowException, OSError, UnicodeDecodeError) as error:
        raise RecorderError(f"{file} cannot be read (truncated or not Parquet): {error}") from error
    if record.get("rows") is not None and table.num_rows != record["rows"]:
        raise RecorderError(f"{file} has {table.num_rows} rows; its header says {record['rows']}")
    expected = {field.name: field.type for field in schema}
    if found != expected:
        differing = sorted(set(expected.items()) ^ set(found.items()), key=str)
        names = ", ".join(dict.fromkeys(name for name, _ in differing))
        raise RecorderError(
            f"{file} does not have the {stream_name(schema)} "
            f"schema (column(s) {names} missing, extra or of another type)"
        )
    return table


def stream_name(schema: pa.Schema) -> str:
    """ "samples", "events" or "scene": the stream a schema describes, for messages."""
    metadata = schema.metadata or {}
    return (metadata.get(b"vascsim.schema") or metadata.get(b"stream") or b"expected").decode()
