"""Remote stations: a simulator station streams its samples to a central recorder over HTTP.

Protocol (one session per station recording): the station POSTs sequenced
batches (Arrow IPC stream bytes of the sample schema) to
``/api/sessions/{session_id}/batches/{sequence}`` with ``Authorization: Bearer
<station token>``. The server appends batch ``n`` to the session's journal only
if it follows batch ``n - 1``; the sequence number is stored in the journal
batch's own metadata and made durable (fsync) before the acknowledgement, so
after a server restart the journal alone says what was accepted. A repeated
batch (``n`` already stored) is acknowledged again without being written:
exactly once. The station keeps every unacknowledged batch in a spool folder on
its own disk and sends them in order when the link returns.

Errors answer ``{"error": "..."}`` with 401 (bad token), 404, 409 (sequence gap,
or time going backwards), 413 (too large), 422 (unknown schema version,
malformed batch, NaN time). Nothing a bad request sends reaches a journal.
"""

from __future__ import annotations

import io
import json
import math
import os
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.ipc as ipc

from recorder.schema import SAMPLE_SCHEMA, SCHEMA_VERSION, RecorderError
from recorder.writer import HEADER_FILE, SAMPLES_JOURNAL, write_json_atomically

MAX_BATCH_BYTES = 8 * 2**20


def encode_batch(batch: pa.RecordBatch) -> bytes:
    """The bytes a station sends: an Arrow IPC stream holding one batch."""
    sink = io.BytesIO()
    with ipc.new_stream(sink, batch.schema) as writer:
        writer.write_batch(batch)
    return sink.getvalue()


class _Session:
    """Server-side state of one session: its journal and the last accepted sequence and time."""

    def __init__(self, directory: Path) -> None:
        self.directory = directory
        self.lock = threading.Lock()
        self.last_sequence, self.last_time = -1, -math.inf
        journal = directory / SAMPLES_JOURNAL
        if journal.exists():  # after a restart the journal is the truth
            self._replay(journal)
        self._sink = open(journal, "ab")
        self._writer: ipc.RecordBatchStreamWriter | None = None

    def _replay(self, journal: Path) -> None:
        """Read back what was accepted; cut a batch torn by a crash so appends stay readable."""
        source = pa.OSFile(str(journal), "rb")
        good = 0
        try:
            reader = ipc.open_stream(source)
            good = source.tell()
            while True:
                try:
                    item = reader.read_next_batch_with_custom_metadata()
                except StopIteration:
                    break
                self.last_sequence = int(item.custom_metadata[b"sequence"])
                if item.batch.num_rows:
                    self.last_time = float(item.batch.column(0)[-1].as_py())
                good = source.tell()
        except (pa.ArrowInvalid, OSError):
            pass  # a torn tail: the batches before it stand
        finally:
            source.close()
        if good < journal.stat().st_size:
            with open(journal, "rb+") as handle:
                handle.truncate(good)
                os.fsync(handle.fileno())

    def close(self) -> None:
        self._sink.close()

    def append(self, sequence: int, batch: pa.RecordBatch) -> None:
        if self._writer is None:
            if self._sink.tell() == 0:
                self._writer = ipc.new_stream(self._sink, SAMPLE_SCHEMA)
            else:  # appending to an existing journal: continue its stream without a new schema message
                self._writer = _ContinuingWriter(self._sink)
        self._writer.write_batch(batch, custom_metadata={"sequence": str(sequence)})
        self._sink.flush()
        os.fsync(self._sink.fileno())
        self.last_sequence = sequence
        if batch.num_rows:
            self.last_time = float(batch.column(0)[-1].as_py())


class _ContinuingWriter:
    """Writes further batch messages onto an IPC stream whose schema message is already on disk."""

    def __init__(self, sink) -> None:
        self._sink = sink

    def write_batch(self, batch: pa.RecordBatch, custom_metadata: dict[str, str]) -> None:
        buffer = io.BytesIO()
        with ipc.new_stream(buffer, batch.schema) as writer:
            writer.write_batch(batch, custom_metadata=custom_metadata)
        schema_bytes = _schema_message_length(batch.schema)
        data = buffer.getvalue()
        self._sink.write(data[schema_bytes:-8])  # drop the schema message and the end-of-stream marker


def _schema_message_length(schema: pa.Schema) -> int:
    buffer = io.BytesIO()
    with ipc.new_stream(buffer, schema):
        pass
    return len(buffer.getvalue()) - 8


class IngestStore:
    """The central recorder's storage: one directory per session under ``root``."""

    def __init__(self, root: str | Path, tokens: dict[str, str] | Callable[[str], str | None]) -> None:
        """tokens: token -> station id, as a mapping or a lookup function (e.g. the catalog's)."""
        self.root = Path(root)
        self.root.mkdir(parents=True, exist_ok=True)
        self._station_of = dict(tokens).get if isinstance(tokens, dict) else tokens
        self._sessions: dict[str, _Session] = {}
        self._lock = threading.Lock()

    def close(self) -> None:
        """Close every session journal (their content is already durable)."""
        with self._lock:
            for session in self._sessions.values():
                session.close()
            self._sessions.clear()

    def station_for(self, authorization: str | None) -> str | None:
        if not authorization or not authorization.startswith("Bearer "):
            return None
        return self._station_of(authorization[len("Bearer ") :])

    def session(self, station: str, session_id: str) -> _Session:
        if not session_id.replace("-", "").replace("_", "").isalnum():
            raise RecorderError(f"session id {session_id!r} must be letters, digits, '-' or '_'")
        with self._lock:
            key = f"{station}/{session_id}"
            if key not in self._sessions:
                directory = self.root / station / session_id
                directory.mkdir(parents=True, exist_ok=True)
                if not (directory / HEADER_FILE).exists():
                    write_json_atomically(
                        directory / HEADER_FILE,
                        {
                            "schema_version": SCHEMA_VERSION,
                            "status": "recording",
                            "station": station,
                            "session": session_id,
                            "flush_interval_s": None,
                        },
                    )
                self._sessions[key] = _Session(directory)
            return self._sessions[key]

    def accept(self, station: str, session_id: str, sequence: int, body: bytes) -> tuple[int, dict[str, Any]]:
        """(HTTP status, JSON answer) for one batch."""
        if len(body) > MAX_BATCH_BYTES:
            return 413, {"error": f"batch of {len(body)} bytes exceeds {MAX_BATCH_BYTES}"}
        try:
            batch = _decode(body)
        except RecorderError as error:
            return 422, {"error": str(error)}
        session = self.session(station, session_id)
        with session.lock:
            if sequence <= session.last_sequence:
                return 200, {"ack": sequence, "duplicate": True}
            if sequence != session.last_sequence + 1:
                return 409, {"error": f"sequence {sequence} arrived, expected {session.last_sequence + 1}"}
            times = batch.column("time").to_numpy()
            if times.size and (np.any(np.diff(times) < 0) or times[0] < session.last_time):
                return 409, {
                    "error": f"batch {sequence} goes back in time (starts at {times[0]:.6f} s, "
                    f"last stored {session.last_time:.6f} s)"
                }
            session.append(sequence, batch)
        return 200, {"ack": sequence, "duplicate": False}


def _decode(body: bytes) -> pa.RecordBatch:
    try:
        reader = ipc.open_stream(body)
        batches = list(reader)
    except (pa.ArrowInvalid, OSError) as error:
        raise RecorderError(f"malformed batch: {error}") from error
    if len(batches) != 1:
        raise RecorderError(f"a request carries exactly one batch; got {len(batches)}")
    batch = batches[0]
    version = (batch.schema.metadata or {}).get(b"vascsim.schema_version")
    if version != str(SCHEMA_VERSION).encode():
        raise RecorderError(f"unknown schema version {version!r}; this server reads {SCHEMA_VERSION}")
    if not batch.schema.equals(SAMPLE_SCHEMA, check_metadata=False):
        raise RecorderError("batch schema differs from the sample schema")
    times = batch.column("time").to_numpy()
    if not np.all(np.isfinite(times)):
        raise RecorderError("time must be finite in every sample (NaN or inf found)")
    return batch


def create_app(store: IngestStore):
    """The ingest web application (Starlette)."""
    from starlette.applications import Starlette
    from starlette.requests import Request
    from starlette.responses import JSONResponse
    from starlette.routing import Route

    async def batches(request: Request) -> JSONResponse:
        station = store.station_for(request.headers.get("authorization"))
        if station is None:
            return JSONResponse({"error": "missing or unknown station token"}, status_code=401)
        body = await request.body()
        try:
            sequence = int(request.path_params["sequence"])
            status, answer = store.accept(station, request.path_params["session_id"], sequence, body)
        except (ValueError, RecorderError) as error:
            return JSONResponse({"error": str(error)}, status_code=422)
        return JSONResponse(answer, status_code=status)

    return Starlette(
        routes=[Route("/api/sessions/{session_id}/batches/{sequence}", batches, methods=["POST"])]
    )


class StationUploader:
    """The station side: spool every batch on local disk, send in order, forget only when acknowledged."""

    def __init__(
        self, url: str, token: str, session_id: str, spool: str | Path, timeout: float = 2.0
    ) -> None:
        import httpx

        self.url, self.session_id = url.rstrip("/"), session_id
        self.spool = Path(spool)
        self.spool.mkdir(parents=True, exist_ok=True)
        self._client = httpx.Client(timeout=timeout, headers={"Authorization": f"Bearer {token}"})
        existing = sorted(int(p.stem) for p in self.spool.glob("*.batch"))
        self._next = (existing[-1] + 1) if existing else self._read_counter()

    def _read_counter(self) -> int:
        counter = self.spool / "next_sequence"
        return int(counter.read_text()) if counter.exists() else 0

    def submit(self, batch: pa.RecordBatch) -> int:
        """Spool a batch durably (it will be sent by ``send_pending``); returns its sequence number."""
        sequence = self._next
        path = self.spool / f"{sequence:012d}.batch"
        temporary = path.with_suffix(".tmp")
        temporary.write_bytes(encode_batch(batch))
        with open(temporary, "rb+") as handle:
            os.fsync(handle.fileno())
        os.replace(temporary, path)
        self._next += 1
        (self.spool / "next_sequence").write_text(str(self._next))
        return sequence

    def send_pending(self) -> int:
        """Send spooled batches in order until one fails; returns how many were acknowledged."""
        import httpx

        sent = 0
        for path in sorted(self.spool.glob("*.batch")):
            sequence = int(path.stem)
            try:
                response = self._client.post(
                    f"{self.url}/api/sessions/{self.session_id}/batches/{sequence}", content=path.read_bytes()
                )
            except httpx.HTTPError:
                return sent  # link down: keep the spool, try again later
            if response.status_code != 200:
                raise RecorderError(
                    f"central recorder refused batch {sequence}: {response.status_code} "
                    f"{json.loads(response.text).get('error', response.text)}"
                )
            path.unlink()
            sent += 1
        return sent

    def close(self) -> None:
        self._client.close()
