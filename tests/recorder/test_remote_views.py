"""A remote station's 3-D view at the central recorder (recorder.remote.views): what is kept, what is
refused before anything is decoded, and the station's sender over a real server (issue 42)."""

from __future__ import annotations

import struct
import time

import cv2
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from starlette.testclient import TestClient

from recorder.remote.ingest import IngestStore
from recorder.remote.routes import create_app
from recorder.remote.station import StationUploader, ViewSender
from recorder.remote.views import MAX_VIEW_BYTES, checked_view, jpeg_size, view_path
from tests.recorder.test_remote import free_port, start_server

TOKEN = {"Authorization": "Bearer secret-station-a"}


def jpeg(width: int = 320, height: int = 180, shade: int = 90) -> bytes:
    image = np.full((height, width, 3), shade, dtype=np.uint8)
    cv2.circle(image, (width // 2, height // 2), min(width, height) // 4, (20, 40, 200), -1)
    ok, data = cv2.imencode(".jpg", image)
    return data.tobytes()


def declaring(body: bytes, width: int, height: int) -> bytes:
    """``body`` with its frame header saying ``width`` x ``height``."""
    at = body.index(b"\xff\xc0")
    return body[: at + 5] + struct.pack(">HH", height, width) + body[at + 9 :]


@pytest.fixture
def ingest(tmp_path):
    store = IngestStore(tmp_path / "central", {"secret-station-a": "station-a"})
    with TestClient(create_app(store)) as client:
        yield client, store
    store.close()


def opened(client, session="v1") -> None:
    answer = client.put(f"/api/sessions/{session}/header", json={"participant_id": "P1"}, headers=TOKEN)
    assert answer.status_code == 200, answer.text


def test_a_jpeg_declares_its_size_and_a_checked_view_is_a_whole_one():
    body = jpeg(320, 180)
    assert jpeg_size(body) == (320, 180) and checked_view(body) == (320, 180)


def test_a_view_of_an_open_session_is_kept_replaced_and_taken_away_at_close(ingest, tmp_path):
    client, store = ingest
    opened(client)
    first, second = jpeg(shade=50), jpeg(shade=200)
    for body in (first, second):
        answer = client.put("/api/sessions/v1/view", content=body, headers=TOKEN)
        assert answer.status_code == 200 and answer.json() == {"view": True, "width": 320, "height": 180}
    kept = view_path(tmp_path / "central", "station-a", "v1")
    assert kept.read_bytes() == second  # only the newest
    assert not (tmp_path / "central" / "station-a" / "v1" / kept.name).exists()  # never in the session
    nothing = {"batches": {"samples": 0, "events": 0}}
    closed = client.post("/api/sessions/v1/close", json=nothing, headers=TOKEN)
    assert closed.status_code == 200, closed.text
    assert not kept.exists()
    late = client.put("/api/sessions/v1/view", content=first, headers=TOKEN)
    assert late.status_code == 409 and "closed" in late.json()["error"]


@pytest.mark.parametrize(
    ("body", "status", "said"),
    [
        (b"GIF89a" + bytes(100), 422, "does not start with the JPEG marker"),
        (jpeg()[:-2], 422, "end-of-image"),
        (declaring(jpeg(), 60000, 60000), 422, "60000x60000 px is outside"),
        (declaring(jpeg(), 0, 180), 422, "0x180 px"),
        (b"\xff\xd8\xff\xe0\x00\x10" + bytes(14) + b"\xff\xd9", 422, "no frame header"),
        (b"\xff\xd8" + bytes(MAX_VIEW_BYTES), 413, "exceeds"),
    ],
    ids=["not-jpeg", "cut-short", "bomb", "zero-wide", "no-frame", "too-big"],
)
def test_a_view_that_is_not_a_sound_jpeg_is_refused_and_nothing_is_kept(ingest, tmp_path, body, status, said):
    client, _ = ingest
    opened(client)
    answer = client.put("/api/sessions/v1/view", content=body, headers=TOKEN)
    assert answer.status_code == status and said in answer.json()["error"]
    assert not view_path(tmp_path / "central", "station-a", "v1").exists()


def test_a_view_needs_the_station_token_and_an_open_session(ingest):
    client, _ = ingest
    assert client.put("/api/sessions/v1/view", content=jpeg()).status_code == 401
    early = client.put("/api/sessions/v9/view", content=jpeg(), headers=TOKEN)
    assert early.status_code == 409 and "send its header first" in early.json()["error"]


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(body=st.binary(max_size=400), cut=st.integers(0, 2000))
def test_hostile_bytes_are_refused_never_a_server_error(ingest, tmp_path, body, cut):
    """Random bytes, and a real JPEG cut anywhere and followed by random bytes: an answer in the one
    shape, 200 only for a JPEG that decodes whole."""
    client, _ = ingest
    opened(client)
    for candidate in (body, b"\xff\xd8" + body, jpeg()[:cut] + body):
        answer = client.put("/api/sessions/v1/view", content=candidate, headers=TOKEN)
        assert answer.status_code in (200, 413, 422), answer.text
        if answer.status_code == 200:
            decoded = cv2.imdecode(np.frombuffer(candidate, np.uint8), cv2.IMREAD_COLOR)
            assert decoded is not None


@pytest.mark.slow
def test_the_station_sends_its_newest_view_over_a_real_server(tmp_path):
    """The station's window replaces its view file; the sender takes each new one to the server, which
    serves the newest; the sender is stopped without waiting on the link."""
    port = free_port()
    server = start_server(tmp_path / "central", port)
    url = f"http://127.0.0.1:{port}"
    uploader = StationUploader(url, "secret-station-a", "w1", tmp_path / "spool")
    frame = tmp_path / "live" / "w1.jpg"
    sender = ViewSender(url, "secret-station-a", "w1", frame, interval=0.02)
    kept = view_path(tmp_path / "central", "station-a", "w1")
    try:
        uploader.set_header({"participant_id": "P1"})
        assert uploader.send_pending() == 1
        sender.start()
        frame.parent.mkdir()
        for shade in (40, 120, 220):
            body = jpeg(shade=shade)
            frame.write_bytes(body)
            deadline = time.monotonic() + 10
            while time.monotonic() < deadline and not (kept.exists() and kept.read_bytes() == body):
                time.sleep(0.02)
            assert kept.read_bytes() == body
        sender.stop()
        assert sender.sent >= 3 and sender.refused == 0
    finally:
        sender.stop()
        uploader.close()
        server.kill()
        server.wait()
