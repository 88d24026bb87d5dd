"""Reading recorded sessions: header, samples and events, checked before they are trusted."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from recorder.layout import EVENTS_FILE, HEADER_FILE, SAMPLES_FILE, SAMPLES_JOURNAL, read_checked, read_header
from recorder.schema import (
    EVENT_SCHEMA,
    OLDER_SAMPLE_SCHEMAS,
    READABLE_VERSIONS,
    SAMPLE_SCHEMA,
    RecorderError,
    upgraded_samples,
)


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
            raise RecorderError(f"{path} was not closed (a crash?)", remedy=("recover", str(path)))
        raise RecorderError(f"{path} is still marked as recording but has no journal")
    if version in OLDER_SAMPLE_SCHEMAS:
        samples = upgraded_samples(
            read_checked(path, SAMPLES_FILE, header.get("samples"), verify, OLDER_SAMPLE_SCHEMAS[version])
        )
    else:
        samples = read_checked(path, SAMPLES_FILE, header.get("samples"), verify, SAMPLE_SCHEMA)
    events = read_checked(path, EVENTS_FILE, header.get("events"), verify, EVENT_SCHEMA)
    times = samples.column("time").to_numpy()
    backwards = np.flatnonzero(np.diff(times) < 0)
    if backwards.size:
        k = int(backwards[0])
        raise RecorderError(
            f"{path / SAMPLES_FILE}: time goes backwards at row {k + 1} "
            f"({times[k + 1]:.6f} s after {times[k]:.6f} s)"
        )
    return Session(path, header, samples, events)


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
