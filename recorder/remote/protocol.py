"""The wire protocol between a simulator station and the central recorder.

A station records a session as two sequenced streams, ``samples`` and
``events``; every batch is an Arrow IPC stream holding one record batch of that
stream's schema, numbered 0, 1, 2, ... per stream. The central recorder
(:mod:`recorder.remote.ingest`) appends batch ``n`` only after batch ``n - 1``, makes
it durable, then acknowledges it; a batch it already holds is acknowledged
again without being written, so a station may resend anything: exactly once.

Two transports carry the same messages (authenticated by ``Authorization:
Bearer <station token>``):

HTTP
    ``PUT /api/sessions/{session}/header`` (JSON object: the session header),
    ``POST /api/sessions/{session}/{stream}/{sequence}`` (batch bytes: sequence and checksum
    in the batch's custom metadata, see ``encode_batch``),
    ``POST /api/sessions/{session}/close`` (JSON ``{"batches": {"samples": n,
    "events": m}, "status": "complete"}``), and, not part of the recording,
    ``PUT /api/sessions/{session}/view`` (the station window's newest frame, a JPEG:
    :mod:`recorder.remote.views`). Answers are JSON: ``{"ack": ...}``
    or ``{"error": "..."}`` with 401, 404, 409, 413 or 422.
WebSocket
    ``/api/sessions/{session}/ws``: binary frames ``stream code (1 byte) |
    sequence (8 bytes, big-endian) | batch bytes``, text frames for the header
    (``{"op": "header", "header": {...}}``) and close (``{"op": "close", ...}``);
    every frame gets one JSON text answer in order, with the HTTP status in it.
"""

from __future__ import annotations

import io
import struct

import numpy as np
import pyarrow as pa
import pyarrow.ipc as ipc

from recorder.integrity import checksum_problem, sealed
from recorder.schema import EVENT_KINDS, EVENT_SCHEMA, SAMPLE_SCHEMA, SCHEMA_VERSION, RecorderError

MAX_BATCH_BYTES = 8 * 2**20
"""Largest batch body the central recorder accepts (8 MiB: ~30 s of samples)."""
MAX_HEADER_BYTES = 64 * 2**10
STREAMS: dict[str, pa.Schema] = {"samples": SAMPLE_SCHEMA, "events": EVENT_SCHEMA}
STREAM_CODES = {"samples": 0, "events": 1}
STREAM_OF_CODE = {code: name for name, code in STREAM_CODES.items()}
FINITE_SAMPLE_COLUMNS = ("time", "force_x", "force_y", "force_z")
"""Sample columns that may never hold NaN or inf (the safety layer never sends a non-finite force)."""
_FRAME_PREFIX = struct.Struct(">BQ")
_VERSION = str(SCHEMA_VERSION).encode()
_EVENT_KINDS = frozenset(EVENT_KINDS)
_FINITE = {
    "samples": [SAMPLE_SCHEMA.get_field_index(name) for name in FINITE_SAMPLE_COLUMNS],
    "events": [EVENT_SCHEMA.get_field_index("time")],
}

CLOSING_STATUSES = ("complete", "failed", "recovered")
"""How a station closes a session: ``recovered`` when it crashed during the session and closes the
central copy later, once the session was recovered on the station (the copy holds what it had sent)."""


class RemoteError(RecorderError):
    """A station's request the central recorder refuses; ``status`` is the HTTP status it answers."""

    def __init__(self, status: int, message: str) -> None:
        super().__init__(message)
        self.status = status


def encode_batch(batch: pa.RecordBatch, sequence: int) -> bytes:
    """The bytes a station sends: an Arrow IPC stream holding one batch, its sequence number and
    the checksum covering batch and sequence (:mod:`recorder.integrity`) in the batch's custom
    metadata (the central recorder stores the batch message exactly as sent)."""
    sink = io.BytesIO()
    with ipc.new_stream(sink, batch.schema) as writer:
        writer.write_batch(batch, custom_metadata=sealed(batch, sequence=str(sequence)))
    return sink.getvalue()


def stream_schema(stream: str) -> pa.Schema:
    try:
        return STREAMS[stream]
    except KeyError:
        raise RemoteError(404, f"unknown stream {stream!r}; streams are {', '.join(STREAMS)}") from None


def decode_batch(stream: str, sequence: int, body: bytes) -> tuple[pa.RecordBatch, bytes]:
    """Check one batch body of ``stream``: its record batch and its IPC batch message (the bytes a
    journal appends); RemoteError (413/422) if it is bad."""
    schema = stream_schema(stream)
    if len(body) > MAX_BATCH_BYTES:
        raise RemoteError(413, f"{stream} batch of {len(body)} bytes exceeds {MAX_BATCH_BYTES}")
    source = pa.BufferReader(body)
    try:
        reader = ipc.open_stream(source)
        schema_end = source.tell()
        item = reader.read_next_batch_with_custom_metadata()
        batch_end = source.tell()
        try:
            reader.read_next_batch()
            raise RemoteError(422, f"a request carries exactly one {stream} batch; got more")
        except StopIteration:
            pass
    except (pa.ArrowException, OSError, ValueError, StopIteration) as error:
        raise RemoteError(422, f"malformed {stream} batch: {error or 'no batch'}") from error
    batch = item.batch
    version = (batch.schema.metadata or {}).get(b"vascsim.schema_version")
    if version != _VERSION:
        raise RemoteError(422, f"unknown schema version {version!r}; this server reads {SCHEMA_VERSION}")
    if not batch.schema.equals(schema, check_metadata=False):
        raise RemoteError(422, f"batch schema differs from the {stream} schema")
    stated = (item.custom_metadata or {}).get(b"sequence")
    if stated is None or not stated.isdigit() or int(stated) != sequence:
        raise RemoteError(422, f"{stream} batch sent as {sequence} says it is {stated!r} in its metadata")
    try:
        batch.validate(full=True)
    except pa.ArrowInvalid as error:
        raise RemoteError(422, f"malformed {stream} batch: {error}") from error
    problem = checksum_problem(batch, item.custom_metadata)
    if problem is not None:  # damaged on the way, or an old station: nothing unverifiable is stored
        raise RemoteError(422, f"{stream} batch {sequence} {problem}")
    for index, field in enumerate(schema):
        # Arrow does not hold data to a field's declared nullability; a null stored here would make
        # the session's Parquet unwritable at close, so it never gets in
        nulls = batch.column(index).null_count
        if nulls and not field.nullable:
            raise RemoteError(
                422, f"{field.name} is declared non-null; this {stream} batch has {nulls} null(s)"
            )
    times = float_values(batch.column(0))
    if times.size > 1 and np.any(np.diff(times) < 0):
        raise RemoteError(422, f"{stream} batch {sequence}: time goes backwards inside the batch")
    for index in _FINITE[stream]:
        column = batch.column(index)
        if column.null_count or not np.isfinite(float_values(column)).all():
            name = schema.field(index).name
            raise RemoteError(422, f"{name} must be finite in every {stream[:-1]} (NaN, inf or null found)")
    if stream == "events":
        unknown = set(batch.column(1).to_pylist()) - _EVENT_KINDS
        if unknown:
            raise RemoteError(422, f"unknown event kind(s) {sorted(map(str, unknown))}")
    return batch, body[schema_end:batch_end]


def float_values(column: pa.Array) -> np.ndarray:
    """A float64 column's values as a NumPy view, without ``to_numpy`` (whose first call imports
    pandas: seconds during which a server answers nothing)."""
    return np.frombuffer(column.buffers()[1], dtype=np.float64, count=len(column), offset=8 * column.offset)


def pack_frame(stream: str, sequence: int, body: bytes) -> bytes:
    """One WebSocket binary frame: stream code, sequence, batch bytes."""
    return _FRAME_PREFIX.pack(STREAM_CODES[stream], sequence) + body


def unpack_frame(frame: bytes) -> tuple[str, int, bytes]:
    if len(frame) < _FRAME_PREFIX.size:
        raise RemoteError(422, f"frame of {len(frame)} bytes is shorter than its 9-byte prefix")
    code, sequence = _FRAME_PREFIX.unpack_from(frame)
    if code not in STREAM_OF_CODE:
        raise RemoteError(404, f"unknown stream code {code}; codes are {STREAM_CODES}")
    return STREAM_OF_CODE[code], sequence, frame[_FRAME_PREFIX.size :]
