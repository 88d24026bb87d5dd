"""The ingest's journals and their group commit: what makes an acknowledged batch durable.

Each stream of a remote session has an append-only journal (the station's Arrow IPC messages, each
carrying its sequence number and checksum). A batch is appended to the page cache on the event loop
and acknowledged only after an fsync that covers it; :class:`GroupCommit` serves many stations with
few fsyncs and one thread hop per round. After a restart a journal replays what was accepted and
cuts what a crash tore (:func:`recorder.integrity.scan_journal`).
"""

from __future__ import annotations

import hashlib
import io
import logging
import math
import os
import threading
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.ipc as ipc

from recorder.integrity import scan_journal
from recorder.remote.protocol import RemoteError

log = logging.getLogger("vascsim.ingest")


def _schema_message(schema: pa.Schema) -> bytes:
    buffer = io.BytesIO()
    with ipc.new_stream(buffer, schema):
        pass
    return buffer.getvalue()[:-8]  # without the end-of-stream marker


class Journal:
    """One stream's append-only journal: the last stored sequence and sample time, and appends."""

    def __init__(self, path: Path, schema: pa.Schema, checksummed: bool = True) -> None:
        """``checksummed``: every stored batch carries its checksum (the header's
        ``journal_checksum``); a journal from before checksums is read without requiring them."""
        self.path, self.schema, self.checksummed = path, schema, checksummed
        self.last_sequence, self.last_time = -1, -math.inf
        self.digests: dict[int, bytes] = {}  # sequence -> SHA-256 of the stored batch message
        self.cut: dict[str, Any] | None = None  # what a restart cut from the journal (damage)
        self._closing = threading.Lock()
        if path.exists():  # after a restart the journal is the truth
            self._replay()
        self._sink = open(path, "ab")
        if self._sink.tell() == 0:
            self._sink.write(_schema_message(schema))
            self._sync()

    def _replay(self) -> None:
        """Read back what was accepted, verifying every batch's checksum; cut what follows the
        verified prefix (a batch torn by a crash, or damaged on disk) so appends stay readable."""
        scan = scan_journal(self.path, self.schema, require_checksums=self.checksummed)
        data = self.path.read_bytes()[: scan.verified_bytes]
        ends = [*scan.offsets[1:], scan.verified_bytes][: len(scan.offsets)]
        for batch, metadata, start, end in zip(scan.batches, scan.metadata, scan.offsets, ends, strict=True):
            self.last_sequence = int(metadata[b"sequence"])
            self.digests[self.last_sequence] = hashlib.sha256(data[start:end]).digest()
            if batch.num_rows:
                self.last_time = float(batch.column(0)[-1].as_py())
        cut = scan.cut()
        if cut is not None:
            self.cut = cut
            log.error("journal %s: cut %d bytes after batch %d: %s", self.path, cut["bytes"],
                      self.last_sequence, cut["reason"])  # fmt: skip
            with open(self.path, "rb+") as handle:
                handle.truncate(len(data))
                os.fsync(handle.fileno())

    def _sync(self) -> None:
        self._sink.flush()
        os.fsync(self._sink.fileno())

    def append(self, sequence: int, batch: pa.RecordBatch, message: bytes) -> None:
        """Append the station's IPC batch message (its sequence in its metadata) to the page cache;
        durable after the next ``fsync`` of ``fileno`` (``sync`` or the group commit)."""
        self._sink.write(message)
        self._sink.flush()
        self.last_sequence = sequence
        self.digests[sequence] = hashlib.sha256(message).digest()
        if batch.num_rows:
            self.last_time = float(batch.column(0)[-1].as_py())

    def sync(self) -> None:
        """Make everything appended so far durable (a closed journal was synced when it closed)."""
        with self._closing:
            if not self._sink.closed:
                os.fsync(self._sink.fileno())

    def close(self) -> None:
        with self._closing:
            if not self._sink.closed:
                self._sync()
                self._sink.close()


class GroupCommit:
    """Makes journals durable for many concurrent writers with few fsyncs and one thread hop.

    The event loop appends (to the page cache) and awaits ``durable(journal)``; one thread
    repeatedly takes every journal waited on, fsyncs each (in parallel, without the interpreter
    lock), then resolves all of that round's waiters in one call into the loop. Anything written
    before ``durable`` was awaited is covered by the round that serves it.
    """

    def __init__(self, parallel_fsyncs: int = 8) -> None:
        from concurrent.futures import ThreadPoolExecutor

        self._waiting: list[tuple[Journal, Any]] = []
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._stop = False
        self._fsyncs = ThreadPoolExecutor(parallel_fsyncs, thread_name_prefix="vascsim-fsync")
        self._thread = threading.Thread(target=self._run, name="vascsim-group-commit", daemon=True)
        self._thread.start()

    async def durable(self, journal: Journal) -> None:
        import asyncio

        future = asyncio.get_running_loop().create_future()
        with self._lock:
            self._waiting.append((journal, future))
        self._wake.set()
        await future

    def _run(self) -> None:
        while True:
            self._wake.wait()
            self._wake.clear()
            with self._lock:
                waiting, self._waiting = self._waiting, []
            if self._stop and not waiting:
                return
            if not waiting:
                continue
            journals = list({id(j): j for j, _ in waiting}.values())
            errors = dict(zip(map(id, journals), self._fsyncs.map(sync_error, journals), strict=True))
            by_loop: dict[Any, list] = {}
            for journal, future in waiting:
                by_loop.setdefault(future.get_loop(), []).append((future, errors[id(journal)]))
            for loop, results in by_loop.items():
                try:
                    loop.call_soon_threadsafe(_resolve, results)
                except RuntimeError:  # that loop has closed: nobody is waiting any more
                    pass

    def close(self) -> None:
        self._stop = True
        self._wake.set()
        self._thread.join()
        self._fsyncs.shutdown()


def sync_error(journal: Journal) -> OSError | None:
    try:
        journal.sync()
    except OSError as error:
        return error
    return None


def outcome_unread(future) -> None:
    """Done-callback of an answer its station left before reading: take its outcome (a refusal or
    a durability error has nobody to go to; what was staged stays in the journal)."""
    if not future.cancelled():
        future.exception()


def _resolve(results: list) -> None:
    for future, error in results:
        if future.done():
            continue
        if error is None:
            future.set_result(None)
        else:
            future.set_exception(RemoteError(503, f"journal could not be made durable: {error}"))
