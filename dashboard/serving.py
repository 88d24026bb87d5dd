"""The HTTP server's guard against slow and numerous clients (issue 45, seen 12).

uvicorn waits for ever on a connection that never finishes its headers, and on a body trickled a
byte at a time: 200 such connections held a server's sockets for minutes. :class:`GuardedH11`
is uvicorn's own HTTP/1.1 protocol with three limits, in the manner of Apache's mod_reqtimeout:

* a request's headers must be complete within ``header_timeout_s`` of its first byte (or of the
  connection opening): otherwise 408 and the connection closes;
* its body must be complete within ``body_timeout_s`` plus one second per ``body_min_rate``
  bytes received, counting only time the server was reading (a body the application has not
  asked for yet is paused by uvicorn's flow control, and that is not the client's slowness);
* at most ``max_connections`` connections at once (WebSockets included): one more is answered 503
  and closed at once.

An idle keep-alive connection is closed by uvicorn's own ``timeout_keep_alive`` (5 s).
"""

from __future__ import annotations

import asyncio
import json
import time
from dataclasses import dataclass

import h11
from uvicorn.protocols.http.h11_impl import H11Protocol

CHECK_INTERVAL_S = 0.25


@dataclass(frozen=True)
class ClientLimits:
    """How long and how many: see the module docstring."""

    header_timeout_s: float = 10.0
    body_timeout_s: float = 10.0
    body_min_rate: float = 500.0  # bytes per second
    max_connections: int = 256


def _answer(status: int, reason: str, message: str) -> bytes:
    """A complete HTTP/1.1 response in the application's error shape, closing the connection."""
    body = json.dumps({"error": {"status": status, "message": message}}).encode()
    head = (
        f"HTTP/1.1 {status} {reason}\r\ncontent-type: application/json\r\n"
        f"content-length: {len(body)}\r\nconnection: close\r\n\r\n"
    )
    return head.encode("ascii") + body


def guarded_protocol(limits: ClientLimits) -> type[H11Protocol]:
    """uvicorn's h11 protocol class bound to ``limits`` (pass it as ``uvicorn.Config(http=...)``)."""

    class Guarded(GuardedH11):
        client_limits = limits

    return Guarded


class GuardedH11(H11Protocol):
    """See the module docstring; ``client_limits`` is set by :func:`guarded_protocol`."""

    client_limits = ClientLimits()

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        if len(self.server_state.connections) >= self.client_limits.max_connections:
            transport.write(
                _answer(
                    503, "Service Unavailable", "too many connections to the dashboard; try again shortly"
                )
            )
            transport.close()
            return
        super().connection_made(transport)
        self._headers_since: float | None = time.monotonic()
        self._body_since: float | None = None
        self._body_bytes = 0
        self._watch = self.loop.call_later(CHECK_INTERVAL_S, self._check)

    def data_received(self, data: bytes) -> None:
        now = time.monotonic()
        if self.conn.their_state is h11.IDLE and self._headers_since is None:
            self._headers_since = now  # the first byte of a request after a kept-alive one
        super().data_received(data)
        state = self.conn.their_state
        if state is not h11.IDLE:
            self._headers_since = None
        if state is h11.SEND_BODY:
            if self._body_since is None:
                self._body_since, self._body_bytes = now, 0
            else:
                self._body_bytes += len(data)
        else:
            self._body_since = None

    def connection_lost(self, exc: Exception | None) -> None:
        watch = getattr(self, "_watch", None)
        if watch is None:  # refused in connection_made: uvicorn never saw it
            return
        watch.cancel()
        super().connection_lost(exc)

    def _check(self) -> None:
        if self.transport.is_closing() or self.transport.get_protocol() is not self:
            return  # closed, or upgraded to a WebSocket (whose own protocol keeps it)
        now = time.monotonic()
        limits = self.client_limits
        if self._body_since is not None and self.flow.read_paused:
            self._body_since += CHECK_INTERVAL_S  # the server is not reading: the clock stops
        if self._headers_since is not None and now - self._headers_since > limits.header_timeout_s:
            return self._cut(f"the request's headers took over {limits.header_timeout_s:g} s")
        if self._body_since is not None:
            allowed = limits.body_timeout_s + self._body_bytes / limits.body_min_rate
            if now - self._body_since > allowed:
                return self._cut(
                    f"the request's body arrived slower than {limits.body_min_rate:g} bytes/s "
                    f"after {limits.body_timeout_s:g} s"
                )
        self._watch = self.loop.call_later(CHECK_INTERVAL_S, self._check)

    def _cut(self, why: str) -> None:
        """408 when no response has begun, then close (the application sees a disconnect)."""
        state = self.conn.our_state  # IDLE: waiting for a request; SEND_RESPONSE: one arrived
        started = self.cycle is not None and self.cycle.response_started
        if state is h11.IDLE or (state is h11.SEND_RESPONSE and not started):
            self.transport.write(_answer(408, "Request Timeout", f"{why}; send requests promptly"))
        self.transport.close()
