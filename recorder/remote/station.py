"""The station side of remote recording: spool every batch on local disk, send in order, forget on ack.

Typical use on a simulator station, next to the local recording::

    uploader = StationUploader("http://central:8000/ingest", token, "s-0042", spool_dir)
    uploader.set_header(header)
    writer = SessionWriter(session_dir, header, mirror=uploader.submit)
    uploader.start()                # sends in the background every 100 ms
    ...                             # the haptic loop records into ``writer``
    writer.close()
    uploader.finish()               # the close request goes last, once every batch is acknowledged
    uploader.stop(timeout=30)       # raises if something is still unsent or was refused

Everything is written to the spool (fsynced) before it is sent and removed only
once acknowledged, so a network cut, a central-recorder restart or a station
restart loses nothing; the central recorder ignores batches it already holds, so
resending produces no duplicates.
"""

from __future__ import annotations

import contextlib
import json
import os
import threading
import time
from pathlib import Path
from typing import Any

import pyarrow as pa

from recorder.layout import HEADER_FILE, write_json_atomically
from recorder.remote.protocol import STREAMS, encode_batch, pack_frame
from recorder.schema import RecorderError

TRANSPORTS = ("http", "websocket")
_WINDOW = 64  # WebSocket frames in flight before waiting for their answers


def _fsync_directory(path: Path) -> None:
    descriptor = os.open(path, os.O_RDONLY)
    try:
        os.fsync(descriptor)
    finally:
        os.close(descriptor)


class StationUploader:
    """Spools a session's header, sample and event batches and close request; sends them in order."""

    def __init__(
        self,
        url: str,
        token: str,
        session_id: str,
        spool: str | Path,
        transport: str = "http",
        timeout: float = 2.0,
        http_client: Any = None,
    ) -> None:
        """url: the central recorder's ingest root (``http://host:port`` or ``.../ingest`` behind the
        dashboard); spool: a folder on this station's disk kept for this session only;
        http_client: an ``httpx.Client`` to send through (TLS settings, proxies), one is made if None."""
        if transport not in TRANSPORTS:
            raise RecorderError(f"transport {transport!r} is not one of {', '.join(TRANSPORTS)}")
        self.url, self.token, self.session_id = url.rstrip("/"), token, session_id
        self.transport, self.timeout = transport, timeout
        self.spool = Path(spool)
        for stream in STREAMS:
            (self.spool / stream).mkdir(parents=True, exist_ok=True)
        self._lock = threading.Lock()  # spooling vs. forgetting acknowledged files
        self._next = self._read_counters()
        self._http = http_client
        self._own_http = http_client is None
        self._socket = None
        self._socket_scope = contextlib.ExitStack()
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self.error: RecorderError | None = None

    # -- spooling ------------------------------------------------------------------------------
    def _read_counters(self) -> dict[str, int]:
        path = self.spool / "next_sequence.json"
        counters = json.loads(path.read_text()) if path.exists() else {}
        for stream in STREAMS:
            spooled = [int(p.stem) for p in (self.spool / stream).glob("*.batch")]
            counters[stream] = max([counters.get(stream, 0), *(s + 1 for s in spooled)])
        return counters

    def set_header(self, header: dict[str, Any]) -> None:
        """Spool the session header (sent before any batch that is still pending)."""
        write_json_atomically(self.spool / HEADER_FILE, header)

    def submit(self, stream: str, batch: pa.RecordBatch) -> int:
        """Spool one batch of ``stream`` durably; returns its sequence number (sending happens later)."""
        if stream not in STREAMS:
            raise RecorderError(f"unknown stream {stream!r}; streams are {', '.join(STREAMS)}")
        if (self.spool / "close.json").exists():
            raise RecorderError(f"session {self.session_id} was finished; no batch can follow")
        with self._lock:
            sequence = self._next[stream]
            body = encode_batch(batch, sequence)
            path = self.spool / stream / f"{sequence:012d}.batch"
            temporary = path.with_suffix(".tmp")
            with open(temporary, "wb") as handle:
                handle.write(body)
                handle.flush()
                os.fsync(handle.fileno())
            os.replace(temporary, path)
            self._next[stream] = sequence + 1
            write_json_atomically(self.spool / "next_sequence.json", self._next)
            _fsync_directory(path.parent)
        return sequence

    def finish(self, status: str = "complete") -> None:
        """Spool the close request: sent once every batch before it is acknowledged."""
        with self._lock:
            write_json_atomically(self.spool / "close.json", {"batches": dict(self._next), "status": status})

    @property
    def pending(self) -> int:
        """Items (header, batches, close) not yet acknowledged."""
        names = (HEADER_FILE, "close.json")
        count = sum((self.spool / name).exists() for name in names)
        return count + sum(len(list((self.spool / stream).glob("*.batch"))) for stream in STREAMS)

    # -- sending -------------------------------------------------------------------------------
    def send_pending(self) -> int:
        """Send everything spooled, in order, until the link fails; returns how many were acknowledged.

        A refusal by the central recorder (a 4xx answer: the batch can never be accepted) raises
        RecorderError naming it; the item stays in the spool for inspection.
        """
        items: list[tuple[str, Path]] = []
        if (self.spool / HEADER_FILE).exists():
            items.append(("header", self.spool / HEADER_FILE))
        for stream in STREAMS:
            items += [(stream, p) for p in sorted((self.spool / stream).glob("*.batch"))]
        closing = self.spool / "close.json"
        if closing.exists():
            items.append(("close", closing))
        send = self._send_http if self.transport == "http" else self._send_websocket
        return send(items)

    def _refused(self, kind: str, path: Path, status: int, message: str) -> RecorderError:
        what = f"{kind} batch {int(path.stem)}" if kind in STREAMS else f"the {kind} request"
        return RecorderError(
            f"central recorder {self.url} refused {what} of session {self.session_id}: {status} {message}"
        )

    def _forget(self, path: Path) -> None:
        with self._lock:
            path.unlink(missing_ok=True)

    def _send_http(self, items: list[tuple[str, Path]]) -> int:
        import httpx

        if self._http is None:
            self._http = httpx.Client(timeout=self.timeout)
        base = f"{self.url}/api/sessions/{self.session_id}"
        auth = {"Authorization": f"Bearer {self.token}"}
        sent = 0
        for kind, path in items:
            method, url = {"header": ("PUT", f"{base}/header"), "close": ("POST", f"{base}/close")}.get(
                kind, ("POST", f"{base}/{kind}/{path.stem.lstrip('0') or '0'}")
            )
            try:
                response = self._http.request(method, url, content=path.read_bytes(), headers=auth)
            except httpx.HTTPError:
                return sent  # link down: keep the spool, try again later
            if response.status_code >= 500:
                return sent  # the server is in trouble: try again later
            if response.status_code != 200:
                try:
                    message = response.json().get("error", response.text)
                except ValueError:
                    message = response.text
                raise self._refused(kind, path, response.status_code, message)
            self._forget(path)
            sent += 1
        return sent

    def _connect_websocket(self):
        from websockets.sync.client import connect

        url = self.url.replace("http://", "ws://", 1).replace("https://", "wss://", 1)
        connection = connect(
            f"{url}/api/sessions/{self.session_id}/ws",
            additional_headers={"Authorization": f"Bearer {self.token}"},
            open_timeout=self.timeout,
            close_timeout=self.timeout,
            max_size=None,
        )
        self._socket_scope = contextlib.ExitStack()  # connect() is meant to be used as a context
        return self._socket_scope.enter_context(connection)

    def _send_websocket(self, items: list[tuple[str, Path]]) -> int:
        from websockets.exceptions import WebSocketException

        sent = 0
        try:
            if self._socket is None:
                self._socket = self._connect_websocket()
            for start in range(0, len(items), _WINDOW):
                window = items[start : start + _WINDOW]
                for kind, path in window:
                    self._socket.send(self._frame(kind, path))
                for kind, path in window:
                    answer = json.loads(self._socket.recv(timeout=self.timeout))
                    if answer.get("status") != 200:
                        self._drop_socket()  # answers still in flight belong to a dead exchange
                        raise self._refused(kind, path, answer.get("status"), answer.get("error", ""))
                    self._forget(path)
                    sent += 1
        except (OSError, TimeoutError, WebSocketException):
            self._drop_socket()  # link down: keep the spool, reconnect next time
        return sent

    def _frame(self, kind: str, path: Path) -> bytes | str:
        if kind == "header":
            return json.dumps({"op": "header", "header": json.loads(path.read_text())})
        if kind == "close":
            return json.dumps({"op": "close", **json.loads(path.read_text())})
        return pack_frame(kind, int(path.stem), path.read_bytes())

    def _drop_socket(self) -> None:
        if self._socket is not None:
            try:
                self._socket_scope.close()
            except Exception:  # a broken link may fail to close in many ways; it is gone either way
                pass
            self._socket = None

    # -- background sending --------------------------------------------------------------------
    def start(self, interval: float = 0.1) -> None:
        """Send pending items every ``interval`` seconds in a background thread."""
        if self._thread is not None:
            raise RecorderError("the uploader is already sending in the background")
        self._stop.clear()
        self._thread = threading.Thread(
            target=self._run, args=(interval,), name="vascsim-uploader", daemon=True
        )
        self._thread.start()

    def _run(self, interval: float) -> None:
        while True:
            try:
                self.send_pending()
            except RecorderError as error:
                self.error = error
                return
            if self._stop.wait(interval):
                return

    def stop(self, timeout: float = 30.0) -> None:
        """Stop background sending after a last attempt to drain the spool (up to ``timeout`` s).

        Raises RecorderError if the central recorder refused something or items are still pending
        (they stay in the spool: a later ``send_pending`` delivers them)."""
        if self._thread is not None:
            self._stop.set()
            self._thread.join()
            self._thread = None
        deadline = time.monotonic() + timeout
        while self.error is None and self.pending and time.monotonic() < deadline:
            try:
                self.send_pending()
            except RecorderError as error:
                self.error = error
            else:
                if self.pending:
                    time.sleep(0.2)
        if self.error is not None:
            raise self.error
        if self.pending:
            raise RecorderError(
                f"{self.pending} item(s) of session {self.session_id} not acknowledged by {self.url} "
                f"within {timeout:g} s; they stay in {self.spool} and are sent by the next send_pending()"
            )

    def close(self) -> None:
        """Release the connection (the spool stays)."""
        if self._http is not None and self._own_http:
            self._http.close()
            self._http = None
        self._drop_socket()


class ViewSender:
    """Sends a station window's newest frame (a JPEG file its window replaces in place) to the central
    recorder's ``PUT /api/sessions/{session}/view``, on its own thread and connection: only the newest
    frame is ever sent, a refused or lost one is dropped, and the recording never waits for a view."""

    def __init__(
        self, url: str, token: str, session_id: str, frame: str | Path, interval: float = 0.1
    ) -> None:
        """frame: the JPEG the station's window publishes (sessions.running.live.live_view_path);
        interval: how often it is looked at (s)."""
        self.url, self.token, self.session_id = url.rstrip("/"), token, session_id
        self.frame, self.interval = Path(frame), interval
        self.sent = self.refused = 0
        self.last_error = ""
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> None:
        self._thread = threading.Thread(target=self._run, name="vascsim-view-sender", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None

    def _run(self) -> None:
        import httpx

        address = f"{self.url}/api/sessions/{self.session_id}/view"
        headers = {"Authorization": f"Bearer {self.token}", "Content-Type": "image/jpeg"}
        seen = None
        with httpx.Client(timeout=2.0) as client:
            while not self._stop.wait(self.interval):
                try:
                    facts = self.frame.stat()
                    version = (facts.st_mtime_ns, facts.st_size)
                    if version == seen:
                        continue
                    body = self.frame.read_bytes()
                except FileNotFoundError:
                    continue  # no window, or not drawn yet
                seen = version
                try:
                    response = client.put(address, content=body, headers=headers)
                except httpx.HTTPError as error:
                    self.refused, self.last_error = self.refused + 1, str(error)
                    continue
                if response.status_code == 200:
                    self.sent += 1
                else:
                    self.refused += 1
                    self.last_error = f"{response.status_code} {response.text}"
