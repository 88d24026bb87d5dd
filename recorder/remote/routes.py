"""The ingest web application (Starlette): the HTTP and WebSocket routes of :mod:`recorder.remote.protocol`.

Batches are checked and appended on the event loop and acknowledged once the group commit has
made them durable; session set-up, header and close (file work) run in worker threads. Every
endpoint is a module-level function reading the :class:`recorder.remote.ingest.IngestStore` from the
application's state, so what each route does is read in one place.
"""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable
from typing import Any

from starlette.applications import Starlette
from starlette.concurrency import run_in_threadpool
from starlette.exceptions import HTTPException
from starlette.requests import HTTPConnection, Request
from starlette.responses import JSONResponse
from starlette.routing import Route, WebSocketRoute
from starlette.websockets import WebSocket, WebSocketDisconnect

from recorder.json_input import JSONInputError, parse_json
from recorder.remote.ingest import IngestStore, _RemoteSession, log
from recorder.remote.journal import outcome_unread
from recorder.remote.protocol import (
    MAX_BATCH_BYTES,
    MAX_HEADER_BYTES,
    RemoteError,
    stream_schema,
    unpack_frame,
)
from recorder.remote.views import MAX_VIEW_BYTES

UNKNOWN_STATION = "missing or unknown station token"


def create_app(store: IngestStore) -> Starlette:
    """The application serving ``store``: routes, and errors in the one shape ({"error": ...})."""
    app = Starlette(
        routes=[
            Route("/api/sessions/{session_id}/header", header, methods=["PUT"]),
            Route("/api/sessions/{session_id}/close", close, methods=["POST"]),
            Route("/api/sessions/{session_id}/view", view, methods=["PUT"]),
            Route("/api/sessions/{session_id}/{stream}/{sequence}", batches, methods=["POST"]),
            WebSocketRoute("/api/sessions/{session_id}/ws", websocket_stream),
        ],
        exception_handlers={HTTPException: http_error, Exception: server_error},
    )
    app.state.ingest_store = store
    return app


def _store(connection: HTTPConnection) -> IngestStore:
    return connection.app.state.ingest_store


def refused(station: str | None, session_id: str, error: RemoteError) -> dict[str, Any]:
    """A refusal as the station reads it, logged with station, session and reason."""
    log.warning("refused station %s session %s: %s %s", station, session_id, error.status, error)
    return {"status": error.status, "error": str(error)}


async def read_body(request: Request, limit: int) -> bytes:
    """The request body, refused (413) as soon as it is known to exceed ``limit`` bytes."""
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
    """The body as JSON (no NaN or infinities, :data:`recorder.json_input.MAX_DEPTH` levels at most),
    at most :data:`MAX_HEADER_BYTES`."""
    try:
        return parse_json(await read_body(request, MAX_HEADER_BYTES), "body")
    except JSONInputError as error:
        raise RemoteError(422, str(error)) from None


async def open_session(store: IngestStore, station: str, session_id: str) -> _RemoteSession:
    opened = store.opened(station, session_id)
    return opened if opened is not None else await run_in_threadpool(store.session, station, session_id)


async def store_batch(
    store: IngestStore, station: str, session_id: str, stream: str, sequence: int, body: bytes
) -> Awaitable[dict[str, Any]]:
    """Stage one batch now (in arrival order); returns an awaitable of its acknowledgement."""
    answer, journal = store.stage(await open_session(store, station, session_id), stream, sequence, body)

    async def acknowledged() -> dict[str, Any]:
        if journal is not None:
            await store.group_commit.durable(journal)
        return answer

    return acknowledged()


async def answer(request: Request, work: Callable[[str], Awaitable[Any]]) -> JSONResponse:
    """Run ``work(station)`` for an authorised station; a refusal in the one error shape."""
    session_id = request.path_params["session_id"]
    station = _store(request).station_for(request.headers.get("authorization"))
    try:
        if station is None:
            raise RemoteError(401, UNKNOWN_STATION)
        return JSONResponse(await work(station))
    except RemoteError as error:
        return JSONResponse({"error": refused(station, session_id, error)["error"]}, status_code=error.status)


async def batches(request: Request) -> JSONResponse:
    """POST a batch: acknowledged once durable."""
    store = _store(request)

    async def work(station: str) -> dict[str, Any]:
        stream, sequence = request.path_params["stream"], request.path_params["sequence"]
        stream_schema(stream)
        if not (sequence.isascii() and sequence.isdigit()):  # "²" is a digit to isdigit(), not to int()
            raise RemoteError(422, f"sequence {sequence!r} is not a non-negative integer")
        body = await read_body(request, MAX_BATCH_BYTES)
        session_id = request.path_params["session_id"]
        return await (await store_batch(store, station, session_id, stream, int(sequence), body))

    return await answer(request, work)


async def header(request: Request) -> JSONResponse:
    """PUT the session's header."""
    return await _with_json_body(request, _store(request).set_header)


async def close(request: Request) -> JSONResponse:
    """POST the session's end: its journals become verified Parquet."""
    return await _with_json_body(request, _store(request).close_session)


async def view(request: Request) -> JSONResponse:
    """PUT the station window's newest frame (a JPEG; recorder.remote.views), checked and kept in a
    worker thread (decoding is file-sized work)."""
    store = _store(request)

    async def work(station: str) -> dict[str, Any]:
        body = await read_body(request, MAX_VIEW_BYTES)
        return await run_in_threadpool(store.set_view, station, request.path_params["session_id"], body)

    return await answer(request, work)


async def _with_json_body(
    request: Request, action: Callable[[str, str, Any], dict[str, Any]]
) -> JSONResponse:
    """``action(station, session, body)`` in a worker thread (file work), with the JSON body."""

    async def work(station: str) -> dict[str, Any]:
        body = await read_json(request)
        return await run_in_threadpool(action, station, request.path_params["session_id"], body)

    return await answer(request, work)


async def text_frame(store: IngestStore, station: str, session_id: str, text: str | None) -> dict[str, Any]:
    """A WebSocket text frame: {"op": "header", "header": {...}} or {"op": "close", ...}."""
    try:
        request = parse_json(text or "", "text frame")
    except JSONInputError as error:
        raise RemoteError(422, str(error)) from None
    op = request.get("op") if isinstance(request, dict) else None
    if op == "header":
        done = await run_in_threadpool(store.set_header, station, session_id, request.get("header"))
    elif op == "close":
        done = await run_in_threadpool(store.close_session, station, session_id, request)
    else:
        raise RemoteError(422, f"unknown operation {op!r}; text frames are 'header' or 'close'")
    return {"status": 200, "op": op, **done}


def _ready(result: dict[str, Any]) -> asyncio.Future:
    future = asyncio.get_running_loop().create_future()
    future.set_result(result)
    return future


async def websocket_stream(websocket: WebSocket) -> None:
    """Frames are handled in arrival order; answers go back in the same order, each batch's once it
    is durable, while later frames are already being checked and appended."""
    store = _store(websocket)
    session_id = websocket.path_params["session_id"]
    station = store.station_for(websocket.headers.get("authorization"))
    await websocket.accept()
    if station is None:
        await websocket.send_json(refused(None, session_id, RemoteError(401, UNKNOWN_STATION)))
        await websocket.close(code=1008, reason=UNKNOWN_STATION)
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

    sender = asyncio.create_task(send_answers())
    try:
        while True:
            message = await websocket.receive()
            if message["type"] == "websocket.disconnect":
                break
            try:
                if message.get("bytes") is not None:
                    stream, sequence, body = unpack_frame(message["bytes"])
                    acknowledged = await store_batch(store, station, session_id, stream, sequence, body)
                    await answers.put(asyncio.ensure_future(acknowledged))
                else:
                    await answers.put(
                        _ready(await text_frame(store, station, session_id, message.get("text")))
                    )
            except RemoteError as error:
                await answers.put(_ready(refused(station, session_id, error)))
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
                    pending.add_done_callback(outcome_unread)


async def http_error(request: Request, error: HTTPException) -> JSONResponse:
    """Routing errors (404, 405 with its Allow header) in the one error shape."""
    return JSONResponse({"error": str(error.detail)}, status_code=error.status_code, headers=error.headers)


async def server_error(request: Request, error: Exception) -> JSONResponse:
    log.exception("ingest request %s %s failed", request.method, request.url.path)
    return JSONResponse({"error": f"internal error: {type(error).__name__}"}, status_code=500)
