"""Hostile input, round 3 (issue 45): nesting that exhausted the JSON parser's recursion, and a
Unicode digit as a sequence number. Each answered 500 or dropped the connection before."""

from __future__ import annotations

import json

import pytest
from starlette.testclient import TestClient

from recorder.json_input import MAX_DEPTH, JSONInputError, parse_json
from recorder.remote.ingest import IngestStore
from recorder.remote.protocol import encode_batch
from recorder.remote.routes import create_app
from tests.recorder.test_remote import AUTH, TOKENS, batch, post

DEEP = "[" * 5000 + "]" * 5000


@pytest.fixture
def http(tmp_path):
    store = IngestStore(tmp_path, TOKENS)
    yield TestClient(create_app(store))
    store.close()


def test_deep_json_in_a_header_or_close_body_is_a_422_in_one_line(http):
    """Seen 1: 500 {"error": "internal error: RecursionError"}."""
    for path, method in (("/api/sessions/s1/header", http.put), ("/api/sessions/s1/close", http.post)):
        answer = method(path, content=DEEP.encode(), headers=AUTH)
        assert answer.status_code == 422, (path, answer.text)
        assert "nests arrays or objects deeper than" in answer.json()["error"]
    assert post(http, 0, encode_batch(batch(0), 0)).status_code == 200  # the session is unharmed


def test_deep_json_in_a_websocket_text_frame_is_answered_and_the_socket_stays_open(http):
    """Seen 2: the connection dropped without a close frame after one acknowledged batch."""
    from recorder.remote.protocol import pack_frame

    with http.websocket_connect("/api/sessions/w1/ws", headers=AUTH) as socket_:
        socket_.send_bytes(pack_frame("samples", 0, encode_batch(batch(0), 0)))
        socket_.send_text(DEEP)
        socket_.send_text(json.dumps({"op": "close", "batches": {"samples": 1, "events": 0}}))
        answers = [socket_.receive_json() for _ in range(3)]
    assert [a["status"] for a in answers] == [200, 422, 200]
    assert "nests arrays or objects deeper than" in answers[1]["error"]


@pytest.mark.parametrize(
    "sequence", ["%C2%B2", "%D9%A3", "%EF%BC%91"]
)  # superscript two, Arabic-Indic three, fullwidth one
def test_a_sequence_number_of_unicode_digits_is_refused(http, sequence):
    """Seen 3: "²".isdigit() is true and int() refuses it: 500 ValueError."""
    answer = http.post(
        f"/api/sessions/s1/samples/{sequence}", content=encode_batch(batch(0), 0), headers=AUTH
    )
    assert answer.status_code == 422 and "is not a non-negative integer" in answer.json()["error"]


def test_parse_json_limits_depth_and_refuses_non_numbers():
    assert parse_json(json.dumps({"a": [[1]]}), "x") == {"a": [[1]]}
    nested = "[" * MAX_DEPTH + "]" * MAX_DEPTH
    assert parse_json(nested, "x") == parse_json(nested, "x")  # exactly the limit is accepted
    for text, said in (
        ("[" * (MAX_DEPTH + 1) + "]" * (MAX_DEPTH + 1), "deeper than"),
        (DEEP, "deeper than"),
        ('{"a": NaN}', "holds NaN"),
        ("[Infinity]", "holds Infinity"),
        ("{", "is not JSON"),
        (b"\xff\xfe", "is not JSON"),
    ):
        with pytest.raises(JSONInputError, match=said):
            parse_json(text, "body")


def test_events_reported_late_are_stored_and_finished_in_time_order(http, tmp_path):
    """Events arrive out of time order from a real-time session (its haptic process's safety events
    come at the end, with the times they happened; a streamed session's close was refused for it):
    stored as they arrive, finished in time order, as a local recording is; samples stay held to it."""
    from recorder import open_session
    from tests.recorder.test_remote import batch, events

    first = encode_batch(events((0.5, "contact_start"), (0.9, "pierce")), 0)
    assert post(http, 0, first, stream="events").status_code == 200
    late = post(http, 1, encode_batch(events((0.2, "force_clamped")), 1), stream="events")
    assert late.status_code == 200, late.text
    assert post(http, 0, encode_batch(batch(100), 0)).status_code == 200
    back = post(http, 1, encode_batch(batch(50), 1))
    assert back.status_code == 409 and "goes back in time" in back.json()["error"]
    closed = http.post("/api/sessions/s1/close", json={"batches": {"samples": 1, "events": 2}}, headers=AUTH)
    assert closed.status_code == 200, closed.text
    stored = open_session(tmp_path / "station-a" / "s1").events
    assert stored.column("time").to_pylist() == [0.2, 0.5, 0.9]
    assert stored.column("kind").to_pylist() == ["force_clamped", "contact_start", "pierce"]


def test_server_owned_header_keys_are_refused_and_an_identical_header_is_a_duplicate(http):
    """Seen 3: a header carrying station, status, received_unix or journal_checksum was stored with
    them overwritten, and re-sending the identical header then answered 409."""
    for key in ("station", "status", "received_unix", "journal_checksum", "session"):
        answer = http.put("/api/sessions/s1/header", json={"participant": "P1", key: "x"}, headers=AUTH)
        assert answer.status_code == 422 and "the central recorder writes these" in answer.json()["error"]
    header = {"participant": "P1", "task": "cube"}
    assert http.put("/api/sessions/s1/header", json=header, headers=AUTH).json() == {"header": True}
    again = http.put("/api/sessions/s1/header", json=header, headers=AUTH)
    assert again.status_code == 200 and again.json()["duplicate"] is True
