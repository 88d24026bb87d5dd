"""Live view of a running station: its recorder journals read as they grow, sent as server-sent events.

The recorder appends Arrow IPC messages to ``samples.arrows`` / ``events.arrows`` and
fsyncs them every flush interval; :class:`JournalTail` reads only the complete
messages added since its last call (a message still being written is left for the
next call), so a view costs one small read per poll however long the session is.
"""

from __future__ import annotations

import asyncio
import json
import math
import time
from collections.abc import AsyncIterator, Callable
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.ipc as ipc
from fastapi import Response

from dashboard.errors import not_found
from recorder.writer import EVENTS_JOURNAL, SAMPLES_JOURNAL

KEEPALIVE_S = 15.0
STATUS_CHECK_S = 2.0


class JournalTail:
    """The record batches appended to an Arrow IPC stream file since the previous call."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.offset = 0
        self.schema: pa.Schema | None = None

    def read_new(self) -> list[pa.RecordBatch]:
        try:
            with open(self.path, "rb") as source:
                source.seek(self.offset)
                data = source.read()
        except FileNotFoundError:
            return []
        reader = pa.BufferReader(pa.py_buffer(data))
        batches, consumed = [], 0
        while True:
            try:
                message = ipc.read_message(reader)
            except (pa.ArrowInvalid, OSError, EOFError):
                break  # the end of what is complete so far
            if message.type == "schema":
                self.schema = ipc.read_schema(message)
            elif message.type == "record batch" and self.schema is not None:
                batches.append(ipc.read_record_batch(message, self.schema))
            consumed = reader.tell()
        self.offset += consumed
        return batches


def sample_payload(
    batches: list[pa.RecordBatch], rate_hz: float, last_bin: float
) -> tuple[dict | None, float]:
    """Force (mN), tip speed (mm/s) and local stress (kPa), the first sample of each 1/``rate_hz`` time bin
    after ``last_bin``; and the last bin sent."""
    if not batches:
        return None, last_bin
    table = pa.Table.from_batches(batches)
    time_s = table.column("time").to_numpy()
    bins = np.floor(time_s * rate_hz)
    keep = np.r_[True, bins[1:] != bins[:-1]] & (bins > last_bin)
    if not keep.any():
        return None, last_bin
    last_bin = float(bins[keep][-1])
    force = np.linalg.norm(
        np.column_stack([table.column(f"force_{a}").to_numpy() for a in "xyz"])[keep], axis=1
    )

    def listed(values: np.ndarray, factor: float) -> list[float | None]:
        return [round(float(v) * factor, 5) if math.isfinite(v) else None for v in values]

    payload = {
        "time": [round(float(t), 4) for t in time_s[keep]],
        "force": listed(force, 1e3),
        "tip_speed": listed(table.column("tip_speed").to_numpy()[keep], 1e3),
        "stress": listed(table.column("local_stress").to_numpy()[keep], 1e-3),
    }
    return payload, last_bin


def event_payloads(batches: list[pa.RecordBatch]) -> list[dict]:
    out = []
    for batch in batches:
        for row in batch.to_pylist():
            angle = row.get("entry_angle_deg")
            out.append(
                {
                    "time": round(float(row["time"]), 4),
                    "kind": row["kind"],
                    "entry_angle_deg": None if angle is None or not math.isfinite(angle) else round(angle, 2),
                }
            )
    return out


def _sse(kind: str, data) -> str:
    return f"event: {kind}\ndata: {json.dumps(data)}\n\n"


async def live_stream(
    directory: Path,
    still_running: Callable[[], bool],
    disconnected: Callable[[], object],
    poll_s: float,
    rate_hz: float,
) -> AsyncIterator[str]:
    """Server-sent events from a session directory's journals until the session stops or the client leaves.

    Events: ``samples`` (arrays), ``event`` (one recorder event), ``end`` (the session stopped)."""
    samples, events = JournalTail(directory / SAMPLES_JOURNAL), JournalTail(directory / EVENTS_JOURNAL)
    last_bin, last_check, last_write = -math.inf, time.monotonic(), time.monotonic()
    yield _sse("hello", {"directory": directory.name})
    while True:
        if await disconnected():
            return
        payload, last_bin = sample_payload(await asyncio.to_thread(samples.read_new), rate_hz, last_bin)
        chunks = [_sse("samples", payload)] if payload else []
        chunks += [_sse("event", item) for item in event_payloads(await asyncio.to_thread(events.read_new))]
        now = time.monotonic()
        if not chunks and now - last_write > KEEPALIVE_S:
            chunks.append(": keep-alive\n\n")
        for chunk in chunks:
            yield chunk
            last_write = now
        if now - last_check > STATUS_CHECK_S:
            last_check = now
            if not await asyncio.to_thread(still_running):
                yield _sse("end", {"reason": "the session is no longer recording"})
                return
        await asyncio.sleep(poll_s)


def newest_view(path: Path, missing: str) -> Response:
    """A station's newest 3-D view, read whole (the station replaces it many times a second: a streamed
    file could change size), never cached; 404 naming ``missing`` when there is none."""
    try:
        frame = path.read_bytes()
    except FileNotFoundError:
        raise not_found(missing) from None
    return Response(frame, media_type="image/jpeg", headers={"Cache-Control": "no-store"})
