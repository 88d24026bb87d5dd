"""The central recorder: remote stations' sessions arrive over HTTP or WebSocket (:mod:`recorder.remote`).

Each session lands in ``root/<station>/<session>/`` as the same files a local
recording writes (``header.json``, then journals, then verified Parquet), so
everything that reads sessions reads these. A batch is appended to its stream's
journal only if it follows the last one stored, with its sequence number in the
journal batch's own metadata, and fsynced before it is acknowledged: after a
server restart the journals alone say what was accepted (a batch torn by the
crash is cut off). Nothing a refused request carries reaches a journal; every
refusal is logged with the station, session and reason.
"""

from __future__ import annotations

import hashlib
import io
import json
import logging
import math
import os
import re
import threading
import time as clock
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.ipc as ipc

from recorder.integrity import CHECKSUM_NAME, scan_journal
from recorder.layout import EVENTS_JOURNAL, HEADER_FILE, SAMPLES_JOURNAL, write_json_atomically
from recorder.remote import (
    MAX_BATCH_BYTES,
    MAX_HEADER_BYTES,
    STREAMS,
    RemoteError,
    decode_batch,
    float_values,
    stream_schema,
    unpack_frame,
)
from recorder.schema import SCHEMA_VERSION
from recorder.writer import finalize

log = logging.getLogger("vascsim.ingest")
JOURNALS = {"samples": SAMPLES_JOURNAL, "events": EVENTS_JOURNAL}
CLOSING_STATUSES = ("complete", "failed")
BATCH_DIGESTS = "batch-digests.json"
"""Written at close: each stored batch's SHA-256 per stream, so a batch re-sent to a closed session
is checked against what was stored, also after a restart (the journals are gone by then)."""
_NAME = re.compile(r"[A-Za-z0-9_-]{1,64}")


def _schema_message(schema: pa.Schema) -> bytes:
    buffer = io.BytesIO()
    with ipc.new_stream(buffer, schema):
        pass
    return buffer.getvalue()[:-8]  # without the end-of-stream marker


class _Journal:
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

        self._waiting: list[tuple[_Journal, Any]] = []
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._stop = False
        self._fsyncs = ThreadPoolExecutor(parallel_fsyncs, thread_name_prefix="vascsim-fsync")
        self._thread = threading.Thread(target=self._run, name="vascsim-group-commit", daemon=True)
        self._thread.start()

    async def durable(self, journal: _Journal) -> None:
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
            errors = dict(zip(map(id, journals), self._fsyncs.map(_sync_error, journals), strict=True))
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


def _sync_error(journal: _Journal) -> OSError | None:
    try:
        journal.sync()
    except OSError as error:
        return error
    return None


def _outcome_unread(future) -> None:
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


def _write_digests(path: Path, digests: dict[str, dict[int, bytes]]) -> None:
    listed = {stream: [digests[stream][k].hex() for k in sorted(digests[stream])] for stream in digests}
    write_json_atomically(path, listed)


def _read_digests(path: Path) -> dict[str, dict[int, bytes]]:
    """The stored batches' digests of a closed session (empty for one closed before they were kept)."""
    if not path.exists():
        return {}
    listed = json.loads(path.read_text())
    return {stream: {k: bytes.fromhex(d) for k, d in enumerate(values)} for stream, values in listed.items()}


class _RemoteSession:
    """Server-side state of one station's session: its journals, or, once closed, its batch counts."""

    def __init__(self, directory: Path, station: str, session_id: str) -> None:
        self.directory = directory
        self.lock = threading.Lock()
        header_path = directory / HEADER_FILE
        if not header_path.exists():
            write_json_atomically(
                header_path,
                {
                    "schema_version": SCHEMA_VERSION,
                    "status": "recording",
                    "station": station,
                    "session": session_id,
                    "flush_interval_s": None,
                    "journal_checksum": CHECKSUM_NAME,
                },
            )
        header = json.loads(header_path.read_text())
        self.closed_counts: dict[str, int] | None = None
        # what each stored batch was, once closed (kept beside the session: the journals are gone)
        self.closed_digests: dict[str, dict[int, bytes]] = {}
        self.journals: dict[str, _Journal] = {}
        if header.get("status") != "recording":
            self.closed_counts = dict(header.get("remote", {}).get("batches", {}))
            self.closed_digests = _read_digests(directory / BATCH_DIGESTS)
        else:
            for stream, schema in STREAMS.items():
                self.journals[stream] = _Journal(
                    directory / JOURNALS[stream], schema, header.get("journal_checksum") == CHECKSUM_NAME
                )

    def close_files(self) -> None:
        for journal in self.journals.values():
            journal.close()


class IngestStore:
    """The central recorder's storage: one directory per station and session under ``root``."""

    def __init__(self, root: str | Path, tokens: dict[str, str] | Callable[[str], str | None]) -> None:
        """tokens: token -> station id, as a mapping or a lookup function (e.g. the catalog's)."""
        self.root = Path(root)
        self.root.mkdir(parents=True, exist_ok=True)
        self._station_of = dict(tokens).get if isinstance(tokens, dict) else tokens
        self._sessions: dict[str, _RemoteSession] = {}
        self._opening: dict[str, threading.Lock] = {}
        self._lock = threading.Lock()
        self._group_commit: GroupCommit | None = None

    @property
    def group_commit(self) -> GroupCommit:
        """The group commit the web application's acknowledgements wait on (started on first use)."""
        with self._lock:
            if self._group_commit is None:
                self._group_commit = GroupCommit()
            return self._group_commit

    def close(self) -> None:
        """Stop the group commit and close every session journal (syncing what is still unsynced)."""
        with self._lock:
            if self._group_commit is not None:
                self._group_commit.close()
                self._group_commit = None
            for session in self._sessions.values():
                session.close_files()
            self._sessions.clear()

    def station_for(self, authorization: str | None) -> str | None:
        if not authorization or not authorization.startswith("Bearer "):
            return None
        return self._station_of(authorization[len("Bearer ") :])

    def opened(self, station: str, session_id: str) -> _RemoteSession | None:
        """The session if it is open already (no file work: safe on an event loop)."""
        return self._sessions.get(f"{station}/{session_id}")

    def session(self, station: str, session_id: str) -> _RemoteSession:
        for kind, name in (("station", station), ("session id", session_id)):
            if not _NAME.fullmatch(name):
                raise RemoteError(422, f"{kind} {name!r} must be 1-64 letters, digits, '-' or '_'")
        key = f"{station}/{session_id}"
        session = self._sessions.get(key)
        if session is not None:
            return session
        with self._opening.setdefault(key, threading.Lock()):  # other sessions open meanwhile
            if key not in self._sessions:
                directory = self.root / station / session_id
                directory.mkdir(parents=True, exist_ok=True)
                opened = _RemoteSession(directory, station, session_id)
                with self._lock:
                    self._sessions[key] = opened
            return self._sessions[key]

    def stage(
        self, session: _RemoteSession, stream: str, sequence: int, body: bytes
    ) -> tuple[dict[str, Any], _Journal | None]:
        """Check one batch and append it to its journal, not yet durable: the acknowledgement to
        send once the returned journal is synced (None: nothing to wait for), or RemoteError."""
        stream_schema(stream)
        if not 0 <= sequence < 2**63:
            raise RemoteError(422, f"sequence {sequence} must be a non-negative 63-bit integer")
        batch, message = decode_batch(stream, sequence, body)
        session_id = session.directory.name
        with session.lock:
            if session.closed_counts is not None:
                if sequence < session.closed_counts.get(stream, 0):
                    known = session.closed_digests.get(stream, {}).get(sequence)
                    if known is not None and known != hashlib.sha256(message).digest():
                        raise RemoteError(
                            409,
                            f"{stream} batch {sequence} was stored with different content before the close",
                        )
                    return {"stream": stream, "ack": sequence, "duplicate": True}, None
                raise RemoteError(
                    409, f"session {session_id} is closed; {stream} batch {sequence} comes too late"
                )
            journal = session.journals[stream]
            if sequence <= journal.last_sequence:  # stored: durable once the journal is synced
                if journal.digests.get(sequence) != hashlib.sha256(message).digest():
                    raise RemoteError(
                        409,
                        f"{stream} batch {sequence} was already stored with different content; "
                        "a sequence number names one batch",
                    )
                return {"stream": stream, "ack": sequence, "duplicate": True}, journal
            if sequence != journal.last_sequence + 1:
                raise RemoteError(
                    409, f"{stream} batch {sequence} arrived, expected {journal.last_sequence + 1}"
                )
            if stream == "samples":
                times = float_values(batch.column(0))
                if times.size and (np.any(np.diff(times) < 0) or times[0] < journal.last_time):
                    raise RemoteError(
                        409,
                        f"samples batch {sequence} goes back in time (starts at {times[0]:.6f} s, "
                        f"last stored {journal.last_time:.6f} s)",
                    )
            journal.append(sequence, batch, message)
        return {"stream": stream, "ack": sequence, "duplicate": False}, journal

    def set_header(self, station: str, session_id: str, header: Any) -> dict[str, Any]:
        """Store the station's session header (participant, task, device, ...); idempotent."""
        if not isinstance(header, dict):
            raise RemoteError(422, "the session header must be a JSON object")
        if header.get("schema_version", SCHEMA_VERSION) != SCHEMA_VERSION:
            raise RemoteError(
                422,
                f"unknown schema version {header['schema_version']!r}; this server reads {SCHEMA_VERSION}",
            )
        _refuse_non_finite(header, "the session header")
        if "ring" in header:  # names a local writer's memory: a central recorder never reads one
            raise RemoteError(422, "the session header's 'ring' is a local recording's own key; leave it out")
        session = self.session(station, session_id)
        with session.lock:
            if session.closed_counts is not None:
                raise RemoteError(409, f"session {session_id} is closed; its header can no longer change")
            current = json.loads((session.directory / HEADER_FILE).read_text())
            if "received_unix" in current:  # the station's header is already stored
                sent = {k: v for k, v in header.items() if k != "schema_version"}
                kept = {k: current.get(k) for k in sent}
                extra = set(current) - set(sent) - _SERVER_HEADER_KEYS
                if kept == sent and not extra:
                    return {"header": True, "duplicate": True}
                raise RemoteError(409, f"session {session_id} already has a header; it is not replaced")
            stored = {
                **header,
                "schema_version": SCHEMA_VERSION,
                "status": "recording",
                "station": station,
                "session": session_id,
                "received_unix": clock.time(),
                "journal_checksum": CHECKSUM_NAME,
            }
            write_json_atomically(session.directory / HEADER_FILE, stored)
        return {"header": True}

    def close_session(self, station: str, session_id: str, request: Any) -> dict[str, Any]:
        """Finish a session once every batch the station sent is stored: journals -> verified Parquet."""
        if not isinstance(request, dict) or not isinstance(request.get("batches"), dict):
            raise RemoteError(422, 'close needs {"batches": {"samples": n, "events": m}, "status": ...}')
        counts = request["batches"]
        if set(counts) != set(STREAMS) or not all(type(n) is int and n >= 0 for n in counts.values()):
            raise RemoteError(422, f"close needs a non-negative batch count for each of {', '.join(STREAMS)}")
        status = request.get("status", "complete")
        if status not in CLOSING_STATUSES:
            raise RemoteError(422, f"status {status!r} is not one of {', '.join(CLOSING_STATUSES)}")
        session = self.session(station, session_id)
        with session.lock:
            if session.closed_counts is not None:
                if session.closed_counts == counts:
                    return {"closed": True, "duplicate": True}
                raise RemoteError(
                    409, f"session {session_id} was closed with batches {session.closed_counts}, not {counts}"
                )
            missing = {
                stream: (journal.last_sequence + 1, counts[stream])
                for stream, journal in session.journals.items()
                if journal.last_sequence + 1 != counts[stream]
            }
            if missing:
                detail = "; ".join(
                    f"{s}: server holds {held}, station sent {sent}" for s, (held, sent) in missing.items()
                )
                raise RemoteError(409, f"session {session_id} cannot close yet ({detail})")
            session.close_files()
            session.closed_digests = {stream: journal.digests for stream, journal in session.journals.items()}
            _write_digests(session.directory / BATCH_DIGESTS, session.closed_digests)
            header = finalize(session.directory, status, {"remote": {"batches": counts}})
            session.journals, session.closed_counts = {}, dict(counts)
        return {
            "closed": True,
            "duplicate": False,
            "rows": {"samples": header["samples"]["rows"], "events": header["events"]["rows"]},
        }


_SERVER_HEADER_KEYS = frozenset(
    {"schema_version", "status", "station", "session", "received_unix", "flush_interval_s"}
    | {"journal_checksum"}
)


def _no_constant(name: str) -> Any:
    raise RemoteError(422, f"body holds {name}, which is not a JSON number")


def _refuse_non_finite(value: Any, what: str) -> None:
    """NaN and infinities are not JSON: a header holding them is refused, never stored."""
    if isinstance(value, float) and not math.isfinite(value):
        raise RemoteError(422, f"{what} holds {value}, which is not a JSON number")
    if isinstance(value, dict):
        for key, item in value.items():
            _refuse_non_finite(item, f"{what}[{key!r}]")
    elif isinstance(value, list):
        for index, item in enumerate(value):
            _refuse_non_finite(item, f"{what}[{index}]")


def create_app(store: IngestStore):
    """The ingest web application (Starlette): the HTTP and WebSocket routes of :mod:`recorder.remote`.

    Batches are checked and appended on the event loop and acknowledged once the group commit
    has made them durable; session set-up, header and close (file work) run in worker threads.
    """
    from starlette.applications import Starlette
    from starlette.concurrency import run_in_threadpool
    from starlette.requests import Request
    from starlette.responses import JSONResponse
    from starlette.routing import Route, WebSocketRoute
    from starlette.websockets import WebSocket, WebSocketDisconnect

    def refused(station: str | None, session_id: str, error: RemoteError) -> dict[str, Any]:
        log.warning("refused station %s session %s: %s %s", station, session_id, error.status, error)
        return {"status": error.status, "error": str(error)}

    async def read_body(request: Request, limit: int) -> bytes:
        declared = request.headers.get("content-length")
        if declared is not None and declared.isdigit() and int(declared) > limit:
            raise RemoteError(413, f"request of {declared} bytes exceeds {limit}")
        body = bytearray()
        async for chunk in request.stream():
            body += chunk
            if len(body) > limit:
                raise RemoteError(413, f"request exceeds {limit} bytes")
        return bytes(body)

    async def read_json(request: Request) -> Any:
        try:
            return json.loads(await read_body(request, MAX_HEADER_BYTES), parse_constant=_no_constant)
        except (json.JSONDecodeError, UnicodeDecodeError) as error:
            raise RemoteError(422, f"body is not JSON: {error}") from error

    async def open_session(station: str, session_id: str) -> _RemoteSession:
        opened = store.opened(station, session_id)
        return opened if opened is not None else await run_in_threadpool(store.session, station, session_id)

    async def store_batch(station: str, session_id: str, stream: str, sequence: int, body: bytes):
        """Stage one batch now (in arrival order); returns an awaitable of its acknowledgement."""
        answer, journal = store.stage(await open_session(station, session_id), stream, sequence, body)

        async def acknowledged() -> dict[str, Any]:
            if journal is not None:
                await store.group_commit.durable(journal)
            return answer

        return acknowledged()

    async def answer(request: Request, work: Callable[[str], Any]) -> JSONResponse:
        session_id = request.path_params["session_id"]
        station = store.station_for(request.headers.get("authorization"))
        try:
            if station is None:
                raise RemoteError(401, "missing or unknown station token")
            return JSONResponse(await work(station))
        except RemoteError as error:
            return JSONResponse(
                {"error": refused(station, session_id, error)["error"]}, status_code=error.status
            )

    async def batches(request: Request) -> JSONResponse:
        async def work(station: str) -> dict[str, Any]:
            stream, sequence = request.path_params["stream"], request.path_params["sequence"]
            stream_schema(stream)
            if not sequence.isdigit():
                raise RemoteError(422, f"sequence {sequence!r} is not a non-negative integer")
            body = await read_body(request, MAX_BATCH_BYTES)
            session_id = request.path_params["session_id"]
            return await (await store_batch(station, session_id, stream, int(sequence), body))

        return await answer(request, work)

    async def header(request: Request) -> JSONResponse:
        async def work(station: str) -> dict[str, Any]:
            body = await read_json(request)
            return await run_in_threadpool(store.set_header, station, request.path_params["session_id"], body)

        return await answer(request, work)

    async def close(request: Request) -> JSONResponse:
        async def work(station: str) -> dict[str, Any]:
            body = await read_json(request)
            return await run_in_threadpool(
                store.close_session, station, request.path_params["session_id"], body
            )

        return await answer(request, work)

    async def text_frame(station: str, session_id: str, text: str | None) -> dict[str, Any]:
        try:
            request = json.loads(text or "", parse_constant=_no_constant)
        except json.JSONDecodeError as error:
            raise RemoteError(422, f"text frame is not JSON: {error}") from error
        op = request.get("op") if isinstance(request, dict) else None
        if op == "header":
            done = await run_in_threadpool(store.set_header, station, session_id, request.get("header"))
        elif op == "close":
            done = await run_in_threadpool(store.close_session, station, session_id, request)
        else:
            raise RemoteError(422, f"unknown operation {op!r}; text frames are 'header' or 'close'")
        return {"status": 200, "op": op, **done}

    async def websocket_stream(websocket: WebSocket) -> None:
        """Frames are handled in arrival order; answers go back in the same order, each batch's
        once it is durable, while later frames are already being checked and appended."""
        import asyncio

        session_id = websocket.path_params["session_id"]
        station = store.station_for(websocket.headers.get("authorization"))
        await websocket.accept()
        if station is None:
            await websocket.send_json(
                refused(None, session_id, RemoteError(401, "missing or unknown station token"))
            )
            await websocket.close(code=1008, reason="missing or unknown station token")
            return
        # Each answer is a task from the moment its frame is staged: a batch's wait for durability
        # joins the next group-commit round at once (not after the answers before it), and an
        # answer the station leaves before reading still runs to its end instead of being dropped.
        answers: asyncio.Queue[asyncio.Future | None] = asyncio.Queue()

        async def send_answers() -> None:
            while (pending := await answers.get()) is not None:
                try:
                    result = {"status": 200, **await pending}
                except RemoteError as error:
                    result = refused(station, session_id, error)
                await websocket.send_json(result)

        def ready(result: dict[str, Any]) -> asyncio.Future:
            future = asyncio.get_running_loop().create_future()
            future.set_result(result)
            return future

        sender = asyncio.create_task(send_answers())
        try:
            while True:
                message = await websocket.receive()
                if message["type"] == "websocket.disconnect":
                    break
                try:
                    if message.get("bytes") is not None:
                        stream, sequence, body = unpack_frame(message["bytes"])
                        acknowledged = await store_batch(station, session_id, stream, sequence, body)
                        await answers.put(asyncio.ensure_future(acknowledged))
                    else:
                        await answers.put(ready(await text_frame(station, session_id, message.get("text"))))
                except RemoteError as error:
                    await answers.put(ready(refused(station, session_id, error)))
        except WebSocketDisconnect:
            pass
        finally:
            await answers.put(None)
            try:
                await sender
            except (WebSocketDisconnect, RuntimeError):
                pass  # the station left before its last answers
            finally:
                while not answers.empty():  # answers nobody will read: their outcome is not needed
                    pending = answers.get_nowait()
                    if pending is not None:
                        pending.add_done_callback(_outcome_unread)

    from starlette.exceptions import HTTPException

    async def http_error(request: Request, error: HTTPException) -> JSONResponse:
        """Routing errors (404, 405 with its Allow header) in the one error shape."""
        return JSONResponse(
            {"error": str(error.detail)}, status_code=error.status_code, headers=error.headers
        )

    async def server_error(request: Request, error: Exception) -> JSONResponse:
        log.exception("ingest request %s %s failed", request.method, request.url.path)
        return JSONResponse({"error": f"internal error: {type(error).__name__}"}, status_code=500)

    return Starlette(
        routes=[
            Route("/api/sessions/{session_id}/header", header, methods=["PUT"]),
            Route("/api/sessions/{session_id}/close", close, methods=["POST"]),
            Route("/api/sessions/{session_id}/{stream}/{sequence}", batches, methods=["POST"]),
            WebSocketRoute("/api/sessions/{session_id}/ws", websocket_stream),
        ],
        exception_handlers={HTTPException: http_error, Exception: server_error},
    )
