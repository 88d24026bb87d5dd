"""A session's end: its journals become verified Parquet files, named with their SHA-256 in the
header, the journals removed last; after a crash, :func:`recover` does the same with what survived
(journals up to their first batch that fails to verify, and the rows the ring still holds).
"""

from __future__ import annotations

import os
import time as clock
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from recorder.batches import read_journal, same_values
from recorder.integrity import CHECKSUM_NAME, scan_journal
from recorder.layout import (
    EVENTS_FILE,
    EVENTS_JOURNAL,
    HEADER_FILE,
    SAMPLES_FILE,
    SAMPLES_JOURNAL,
    read_header,
    sha256_of,
    write_json_atomically,
)
from recorder.ring import release_ring, salvage_ring
from recorder.schema import EVENT_SCHEMA, SAMPLE_SCHEMA, SCHEMA_VERSION, RecorderError


def finalize(
    directory: Path, status: str, extra: dict[str, Any] | None = None, salvaged: pa.RecordBatch | None = None
) -> dict[str, Any]:
    """Journals -> verified Parquet files with SHA-256 in the header; journals removed last.

    Each journal is read up to its first batch that fails to verify; what was cut is recorded in
    the header (``samples.cut`` / ``events.cut``). ``salvaged``: sample rows recovered from the
    recording's memory after the journal's last batch (see ``recover``)."""
    header = read_header(directory)
    required = header.get("journal_checksum") == CHECKSUM_NAME
    staged: list[tuple[Path, Path]] = []  # (verified temporary, its final name): replaced together
    try:
        for journal, target, schema, key in (
            (SAMPLES_JOURNAL, SAMPLES_FILE, SAMPLE_SCHEMA, "samples"),
            (EVENTS_JOURNAL, EVENTS_FILE, EVENT_SCHEMA, "events"),
        ):
            if not (directory / journal).is_file():
                raise RecorderError(f"{directory / journal} is missing; the session cannot be finished")
            scan = scan_journal(directory / journal, schema, required)
            batches = scan.batches + ([salvaged] if key == "samples" and salvaged is not None else [])
            table = pa.Table.from_batches(batches, schema=schema)
            if key == "events":  # recorded as they arrived (a layer in another process reports late)
                table = table.sort_by([("time", "ascending")])  # stable: one time keeps its order
            temporary = directory / (target + ".tmp")
            staged.append((temporary, directory / target))
            pq.write_table(table, temporary, compression="zstd")
            if not same_values(pq.read_table(temporary), table):
                raise RecorderError(f"verification of {temporary} failed; the journal {journal} is kept")
            header[key] = _stream_entry(target, temporary, table, scan.cut())
        for temporary, final in staged:  # only once both verified: a failure leaves no Parquet behind
            os.replace(temporary, final)
    finally:
        for temporary, _ in staged:
            temporary.unlink(missing_ok=True)
    header.update(extra or {})
    header["status"] = status
    header["closed_unix"] = clock.time()
    write_json_atomically(directory / HEADER_FILE, header)
    for journal in (SAMPLES_JOURNAL, EVENTS_JOURNAL):
        (directory / journal).unlink(missing_ok=True)
    return header


def _stream_entry(name: str, written: Path, table: pa.Table, cut: dict[str, Any] | None) -> dict[str, Any]:
    """A finished stream's header entry: its file, rows, SHA-256, time range and what was cut."""
    entry: dict[str, Any] = {"file": name, "rows": table.num_rows, "sha256": sha256_of(written)}
    entry["torn_tail_cut"] = cut is not None
    if cut is not None:
        entry["cut"] = cut
    if name == SAMPLES_FILE and table.num_rows:
        times = table.column("time").to_numpy()
        entry["time_range_s"] = [float(times[0]), float(times[-1])]
    return entry


def recover(directory: str | Path) -> dict[str, Any]:
    """Turn the journals a crash left behind into a valid session marked ``recovered``.

    The journals are kept up to their first batch that fails to verify (torn or damaged: what
    was cut is recorded). If the recording process died but the machine did not, its ring
    (tmpfs) still holds every row it recorded: rows after the journal's last batch are checked
    and kept, and the header says so. The header records, measured: the last durable sample
    (``durable_until_s``), the last kept one (``recovered_until_s``), the time between them
    (``unflushed_s``) and what may be lost (``lost_at_most_s``: 0 when the ring accounted for
    every recorded row, null when the ring was gone and the extent is unknown).
    """
    directory = Path(directory)
    if not (directory / SAMPLES_JOURNAL).exists():
        raise RecorderError(f"{directory} has no journal to recover (nothing was being recorded there)")
    if not (directory / HEADER_FILE).exists():
        raise RecorderError(f"{directory} has a journal but no header.json; cannot tell which session it is")
    header = read_header(directory)
    if header.get("schema_version") != SCHEMA_VERSION:
        raise RecorderError(
            f"{directory / HEADER_FILE}: schema version {header.get('schema_version')!r} is not one this "
            f"vascsim writes ({SCHEMA_VERSION}); the journal is left as it is"
        )
    required = header.get("journal_checksum") == CHECKSUM_NAME
    durable, _ = read_journal(directory / SAMPLES_JOURNAL, SAMPLE_SCHEMA, required)
    salvaged, ring, problem = salvage_ring(header, durable)
    durable_until = float(durable.column("time")[-1].as_py()) if durable.num_rows else None
    kept_until = float(salvaged.column(0)[-1].as_py()) if salvaged is not None else durable_until
    interval = header.get("flush_interval_s")
    if ring is not None:
        missing = ring["dropped_unflushed"]
        note = (
            f"every sample recorded was kept ({durable.num_rows} from the journal, "
            f"{0 if salvaged is None else salvaged.num_rows} from the recording's memory)"
            + (f"; {missing} samples the recorder could not keep up with were dropped" if missing else "")
            + (f"; events after {durable_until:.3f} s may be missing" if durable_until is not None else "")
        )
    else:
        note = (
            f"{problem}: samples recorded after the last durable one were lost and how many is "
            f"unknown (the writer made its journal durable every {interval} s)"
        )
    lost = {
        "recovered": True,
        "durable_until_s": durable_until,
        "recovered_until_s": kept_until,
        "lost_after_s": kept_until,
        "unflushed_s": None if durable_until is None or kept_until is None else kept_until - durable_until,
        "salvaged_samples": 0 if salvaged is None else salvaged.num_rows,
        "lost_at_most_s": 0.0 if ring is not None else None,
        "loss_note": note,
    }
    if ring is not None and ring["dropped_unflushed"]:
        lost["dropped_samples"] = header.get("dropped_samples", 0) + ring["dropped_unflushed"]
    finished = finalize(directory, "recovered", lost, salvaged)
    release_ring(header)
    return finished
