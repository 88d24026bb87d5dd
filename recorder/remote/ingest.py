"""The central recorder: remote stations' sessions arrive over HTTP or WebSocket
(:mod:`recorder.remote.protocol`).

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
import json
import logging
import math
import re
import threading
import time as clock
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from recorder.integrity import CHECKSUM_NAME
from recorder.layout import EVENTS_JOURNAL, HEADER_FILE, SAMPLES_JOURNAL, write_json_atomically
from recorder.remote.journal import GroupCommit, Journal
from recorder.remote.protocol import (
    CLOSING_STATUSES,
    STREAMS,
    RemoteError,
    decode_batch,
    float_values,
    stream_schema,
)
from recorder.remote.views import checked_view, keep_view, view_path
from recorder.schema import SCHEMA_VERSION
from recorder.writer import finalize

log = logging.getLogger("vascsim.ingest")
JOURNALS = {"samples": SAMPLES_JOURNAL, "events": EVENTS_JOURNAL}
BATCH_DIGESTS = "batch-digests.json"
"""Written at close: each stored batch's SHA-256 per stream, so a batch re-sent to a closed session
is checked against what was stored, also after a restart (the journals are gone by then)."""
_NAME = re.compile(r"[A-Za-z0-9_-]{1,64}")


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
        self.journals: dict[str, Journal] = {}
        if header.get("status") != "recording":
            self.closed_counts = dict(header.get("remote", {}).get("batches", {}))
            self.closed_digests = _read_digests(directory / BATCH_DIGESTS)
        else:
            for stream, schema in STREAMS.items():
                self.journals[stream] = Journal(
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
    ) -> tuple[dict[str, Any], Journal | None]:
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
            # samples in time order across batches; events as they arrive (a real-time session's
            # haptic process reports its events at the end, with the times they happened), put in
            # time order when the session is finished (recorder.finalize)
            times = float_values(batch.column(0))
            ordered = stream == "samples"
            if ordered and times.size and (np.any(np.diff(times) < 0) or times[0] < journal.last_time):
                raise RemoteError(
                    409,
                    f"{stream} batch {sequence} goes back in time (starts at {times[0]:.6f} s, "
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
        owned = sorted(set(header) & (_SERVER_HEADER_KEYS - {"schema_version"}))
        if owned:  # written by this server; a station's value would be overwritten, or believed
            raise RemoteError(
                422,
                f"the session header's {', '.join(map(repr, owned))}: the central recorder writes "
                "these; leave them out",
            )
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

    def set_view(self, station: str, session_id: str, body: bytes) -> dict[str, Any]:
        """Keep ``body`` as the newest 3-D view of an open session (recorder.remote.views): checked
        completely first; refused (409) before the session's first header or batch and after its close."""
        width, height = checked_view(body)
        session = self.opened(station, session_id)
        if session is None:
            raise RemoteError(409, f"session {session_id} is not open here; send its header first")
        with session.lock:
            if session.closed_counts is not None:
                raise RemoteError(409, f"session {session_id} is closed; its view is no longer shown")
            keep_view(view_path(self.root, station, session_id), body)
        return {"view": True, "width": width, "height": height}

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
            view_path(self.root, station, session_id).unlink(missing_ok=True)
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
