"""Per-batch checksums, so a damaged journal is cut where the damage starts instead of laundered.

Every record batch a journal holds (a local recording's ``samples.arrows`` /
``events.arrows``, a central recorder's journals, a station's spooled batches)
carries in its IPC custom metadata a CRC-32 of the batch's serialized message
(its layout and every buffer) and of its other custom metadata (the sequence
number a station sends). Reading a journal back recomputes it: a batch whose
bytes changed (a bit flip on disk, a torn write that still parses, an edit)
no longer matches and the journal's verified prefix ends there.

CRC-32 detects every single-bit error and every burst up to 32 bits, which is
what storage damage looks like; it is not a signature (anyone who edits a batch
can recompute it), so it proves integrity against accidents, not provenance.
"""

from __future__ import annotations

import zlib
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.ipc as ipc

from recorder.schema import RecorderError

CHECKSUM_KEY = b"vascsim.crc32"
CHECKSUM_NAME = "crc32"
"""The value a header's ``journal_checksum`` names: every journal batch carries ``CHECKSUM_KEY``."""


def batch_checksum(batch: pa.RecordBatch, metadata: Mapping[bytes, bytes] | None = None) -> str:
    """CRC-32 (8 hex digits) of ``batch``'s IPC message and of ``metadata`` other than the checksum."""
    crc = zlib.crc32(batch.serialize())
    for key in sorted(metadata or {}):
        if key != CHECKSUM_KEY:
            crc = zlib.crc32(b"%b=%b\n" % (key, metadata[key]), crc)
    return f"{crc:08x}"


def sealed(batch: pa.RecordBatch, **metadata: str) -> dict[str, str]:
    """Custom metadata for writing ``batch``: ``metadata`` plus the checksum covering both."""
    encoded = {key.encode(): value.encode() for key, value in metadata.items()}
    return {**metadata, CHECKSUM_KEY.decode(): batch_checksum(batch, encoded)}


def checksum_problem(batch: pa.RecordBatch, metadata: Mapping[bytes, bytes] | None) -> str | None:
    """Why ``batch`` with its read-back custom metadata fails verification, or None if it passes."""
    stated = (metadata or {}).get(CHECKSUM_KEY)
    if stated is None:
        return "carries no checksum"
    actual = batch_checksum(batch, metadata)
    if stated.decode(errors="replace") != actual:
        return f"checksum {stated.decode(errors='replace')!r} does not match its content ({actual})"
    return None


@dataclass
class JournalScan:
    """What reading an IPC journal back found: its verified prefix and why it ends where it does."""

    batches: list[pa.RecordBatch]
    metadata: list[Mapping[bytes, bytes]]
    offsets: list[int]
    """Byte offset of each batch's message: batch i is ``offsets[i]:offsets[i + 1]`` (the last
    ends at ``verified_bytes``)."""
    verified_bytes: int
    """Length of the verified prefix (schema message and every verified batch)."""
    total_bytes: int
    problem: str | None
    """Why reading stopped before the end (None: the whole journal verified)."""

    def cut(self) -> dict[str, Any] | None:
        """What was cut, for a header: None when nothing was."""
        if self.problem is None and self.verified_bytes >= self.total_bytes:
            return None
        return {
            "after_batches": len(self.batches),
            "bytes": self.total_bytes - self.verified_bytes,
            "reason": self.problem or "incomplete batch at the end (torn write)",
        }


def scan_journal(path: Path, schema: pa.Schema, require_checksums: bool) -> JournalScan:
    """Read ``path`` batch by batch, verifying each, up to the first that does not verify.

    require_checksums: every batch must carry a matching checksum (journals written since
    checksums exist; their header says ``journal_checksum``). Without it a batch is checked if it
    carries one, and once one batch did, every later batch must. RecorderError if the journal
    holds another schema (a damaged or foreign journal header).
    """
    data = path.read_bytes()
    batches: list[pa.RecordBatch] = []
    metadata: list[Mapping[bytes, bytes]] = []
    offsets: list[int] = []
    problem, verified = None, 0
    source = pa.BufferReader(data)
    try:
        reader = ipc.open_stream(source)
        verified = source.tell()
        if not reader.schema.equals(schema, check_metadata=False):
            kind = (schema.metadata or {}).get(b"vascsim.schema", b"stream").decode()
            raise RecorderError(f"{path} does not hold the {kind} schema (damaged journal header)")
        while True:
            try:
                item = reader.read_next_batch_with_custom_metadata()
            except StopIteration:
                verified = source.tell()  # the end-of-stream marker of a closed journal
                break
            item.batch.validate(full=True)
            found = dict(item.custom_metadata or {})
            if require_checksums or CHECKSUM_KEY in found:
                problem = checksum_problem(item.batch, found)
                if problem is not None:
                    problem = f"batch {len(batches)} {problem}"
                    break
                require_checksums = True
            batches.append(item.batch)
            metadata.append(found)
            offsets.append(verified)
            verified = source.tell()
    except (pa.ArrowException, OSError, EOFError, ValueError) as error:
        problem = f"batch {len(batches)} is unreadable ({error})" if verified else f"unreadable ({error})"
    finally:
        source.close()
    if problem is None and verified < len(data):
        problem = "incomplete batch at the end (torn write)"
    return JournalScan(batches, metadata, offsets, verified, len(data), problem)
