"""Issue 45, seen 12: slow clients are cut off and the number of connections is bounded.

Before: 200 connections with unfinished headers were still open after 70 s, and a body trickled at
1 byte per 2 s was not cut after 20 s (`uvicorn.run` with no timeouts or connection limit). Each
check runs against `vascsim serve` itself, with short limits so the test is quick."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
from contextlib import ExitStack
from pathlib import Path

import httpx
import pytest

from tests.dashboard.test_cli import _first_answer

LIMITS = {"header_timeout_s": "1", "body_timeout_s": "1", "body_min_rate": "10", "max_connections": "40"}


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    """(port, a station's ingest token) of `vascsim serve` with the short LIMITS."""
    from sessions.catalog import Catalog
    from sessions.catalog.accounts import create_station_token
    from sessions.config import database_url

    home = tmp_path_factory.mktemp("slow") / "home"
    home.mkdir()
    catalog = Catalog(database_url(home))
    with catalog.session() as orm:
        _, token = create_station_token(orm, "station-a")
    catalog.close()
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    env = dict(os.environ, VASCSIM_HOME=str(home))
    env.pop("VASCSIM_DATABASE_URL", None)
    settings = [item for name, value in LIMITS.items() for item in ("--setting", f"{name}={value}")]
    arguments = [str(Path(sys.executable).with_name("vascsim")), "serve", "--port", str(port), *settings]
    with subprocess.Popen(arguments, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE) as server:
        try:
            _first_answer(server, f"http://127.0.0.1:{port}/login")
            yield port, token
        finally:
            server.terminate()
            server.wait(20)


def _connect(port: int) -> socket.socket:
    client = socket.create_connection(("127.0.0.1", port), timeout=10)
    client.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    return client


def _answer_and_close(client: socket.socket, within_s: float) -> bytes:
    """Everything the server sends until it closes the connection; fails if it is still open
    after ``within_s``."""
    client.settimeout(within_s)
    received = b""
    try:
        while chunk := client.recv(4096):
            received += chunk
    except TimeoutError:
        raise AssertionError(f"still open after {within_s} s; received {received[:80]!r}") from None
    return received


def _wait_until_quiet(port: int) -> None:
    """Until a plain request is served again (the previous check's connections are gone)."""
    deadline = time.monotonic() + 15
    while httpx.get(f"http://127.0.0.1:{port}/login").status_code != 200:
        if time.monotonic() > deadline:
            raise AssertionError("the server did not recover")
        time.sleep(0.2)


def test_connections_that_never_finish_their_headers_are_answered_408_and_closed(served):
    port, _ = served
    with ExitStack() as stack:
        started = time.monotonic()
        clients = [stack.enter_context(_connect(port)) for _ in range(30)]
        for client in clients[::2]:  # half send part of a request, half send nothing at all
            client.sendall(b"GET /login HTTP/1.1\r\nHost: 127.0.0.1\r\n")
        answers = [_answer_and_close(client, within_s=6) for client in clients]
        assert time.monotonic() - started < 6
    for answer in answers:
        assert answer.startswith(b"HTTP/1.1 408 Request Timeout\r\n"), answer
        assert b'"message": "the request\'s headers took over 1 s; send requests promptly"' in answer
    _wait_until_quiet(port)


def test_a_trickled_body_is_cut_and_a_slow_but_steady_client_is_served(served):
    port, _ = served
    with _connect(port) as client:
        started = time.monotonic()
        client.sendall(
            b"POST /api/login HTTP/1.1\r\nHost: 127.0.0.1\r\ncontent-type: application/json\r\n"
            b"content-length: 60\r\n\r\n"
        )
        client.settimeout(0.5)
        received = b""
        for _ in range(40):  # one byte every 0.5 s: 2 bytes/s, under the 10 bytes/s required
            try:
                client.sendall(b" ")
                received += client.recv(4096)
                if received and not client.recv(4096):
                    break
            except TimeoutError:
                continue
            except (BrokenPipeError, ConnectionResetError):
                break
        elapsed = time.monotonic() - started
    assert received.startswith(b"HTTP/1.1 408 Request Timeout\r\n"), received
    assert b"slower than 10 bytes/s after 1 s" in received and elapsed < 4, (elapsed, received)
    with _connect(port) as client:  # headers in three parts within the limit: served as usual
        for part in (b"GET /login HTTP/1.1\r\n", b"Host: 127.0.0.1\r\n", b"Connection: close\r\n\r\n"):
            client.sendall(part)
            time.sleep(0.25)
        assert _answer_and_close(client, within_s=10).startswith(b"HTTP/1.1 200 OK\r\n")


def test_connections_past_the_limit_are_answered_503_at_once(served):
    port, _ = served
    with ExitStack() as stack:
        idle = [stack.enter_context(_connect(port)) for _ in range(40)]
        time.sleep(0.3)  # all accepted
        with _connect(port) as one_more:
            answer = _answer_and_close(one_more, within_s=2)
        assert (
            answer.startswith(b"HTTP/1.1 503 Service Unavailable\r\n") and b"too many connections" in answer
        )
        assert all(_answer_and_close(client, within_s=6).startswith(b"HTTP/1.1 408") for client in idle)
    _wait_until_quiet(port)


def test_a_quiet_websocket_stream_is_not_cut(served):
    """A station's WebSocket sits idle past every limit and is still served (the guard is HTTP's)."""
    from websockets.sync.client import connect

    port, token = served
    address = f"ws://127.0.0.1:{port}/ingest/api/sessions/s1/ws"
    with connect(address, additional_headers={"Authorization": f"Bearer {token}"}) as stream:
        time.sleep(2.5)
        stream.send("{not json")
        reply = stream.recv(timeout=10)
    assert "JSON" in reply or "json" in reply, reply
