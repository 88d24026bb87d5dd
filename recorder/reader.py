"""Reading recorded sessions: header, samples and events, checked before they are trusted."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from recorder.schema import (
    EVENT_SCHEMA,
    READABLE_VERSIONS,
    SAMPLE_SCHEMA,
    SAMPLE_SCHEMA_V1,
    RecorderError,
    upgraded_samples,
)
from recorder.writer import EVENTS_FILE, HEADER_FILE, SAMPLES_FILE, SAMPLES_JOURNAL, read_header, sha256_of


@dataclass(frozen=True)
class Session:
    """One recorded session: its header and its sample and event tables (Arrow)."""

    path: Path
    header: dict[str, Any]
    samples: pa.Table
    events: pa.Table

    def samples_frame(self, library: str = "pandas"):
        """The samples as a pandas or polars DataFrame."""
        return _frame(self.samples, library)

    def events_frame(self, library: str = "pandas"):
        return _frame(self.events, library)


def _frame(table: pa.Table, library: str):
    if library == "pandas":
        return table.to_pandas()
    if library == "polars":
        import polars as pl

        return pl.from_arrow(table)
    raise RecorderError(f"frames are 'pandas' or 'polars'; got {library!r}")


def open_session(path: str | Path, verify: bool = True) -> Session:
    """Open a closed (or recovered) session directory; raises RecorderError naming what is wrong."""
    path = Path(path)
    header = read_header(path)
    version = header.get("schema_version")
    if version not in READABLE_VERSIONS:
        raise RecorderError(
            f"{path}: schema version {version!r} is not one this vascsim reads "
            f"(it reads versions {', '.join(map(str, READABLE_VERSIONS))})"
        )
    if header.get("status") == "recording":
        if (path / SAMPLES_JOURNAL).exists():
            raise RecorderError(f"{path} was not closed (a crash?); run `vascsim recover {path}` first")
        raise RecorderError(f"{path} is still marked as recording but has no journal")
    if version == 1:
        samples = upgraded_samples(
            _read_checked(path, SAMPLES_FILE, header.get("samples"), verify, SAMPLE_SCHEMA_V1)
        )
    else:
        samples = _read_checked(path, SAMPLES_FILE, header.get("samples"), verify, SAMPLE_SCHEMA)
    events = _read_checked(path, EVENTS_FILE, header.get("events"), verify, EVENT_SCHEMA)
    times = samples.column("time").to_numpy()
    backwards = np.flatnonzero(np.diff(times) < 0)
    if backwards.size:
        k = int(backwards[0])
        raise RecorderError(
            f"{path / SAMPLES_FILE}: time goes backwards at row {k + 1} "
            f"({times[k + 1]:.6f} s after {times[k]:.6f} s)"
        )
    return Session(path, header, samples, events)


def _read_checked(path: Path, name: str, record: Any, verify: bool, schema: pa.Schema) -> pa.Table:
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
            f"{file} does not have the {_stream_name(schema)} "
            f"schema (column(s) {names} missing, extra or of another type)"
        )
    return table


def list_sessions(root: str | Path) -> tuple[list[Session], dict[Path, str]]:
    """Every readable session below ``root``, and for each unreadable one the reason (one bad file
    never stops the others from being listed)."""
    good, bad = [], {}
    for header in sorted(Path(root).rglob(HEADER_FILE)):
        try:
            good.append(open_session(header.parent))
        except RecorderError as error:
            bad[header.parent] = str(error)
    return good, bad


def _stream_name(schema: pa.Schema) -> str:
    """ "samples", "events" or "scene": the stream a schema describes, for messages."""
    metadata = schema.metadata or {}
    return (metadata.get(b"vascsim.schema") or metadata.get(b"stream") or b"expected").decode()
