"""Issue 23, part 1: no acknowledged batch can make a session unclosable; conflicts are refused;
every error has the one JSON shape. Each case failed on the landed code."""

from __future__ import annotations

import json

import numpy as np
import pyarrow as pa
import pytest
from starlette.testclient import TestClient

from recorder import open_session
from recorder.remote.ingest import IngestStore
from recorder.remote.protocol import encode_batch
from recorder.remote.routes import create_app
from recorder.schema import EVENT_SCHEMA
from tests.recorder.test_remote import AUTH, TOKENS, batch, events, post

CLOSE = {"batches": {"samples": 1, "events": 0}, "status": "complete"}


@pytest.fixture
def client(tmp_path):
    store = IngestStore(tmp_path, TOKENS)
    yield TestClient(create_app(store)), tmp_path
    store.close()


def _with_nulls(record: pa.RecordBatch, name: str) -> pa.RecordBatch:
    index = record.schema.get_field_index(name)
    values = record.column(index).to_pylist()
    values[2] = None
    return record.set_column(
        index, record.schema.field(name), pa.array(values, type=record.schema.field(name).type)
    )


def test_a_null_in_a_non_null_sample_column_is_refused_and_the_session_still_closes(client):
    """Seen: nulls in tool_x answered 200; every later close was a plain-text 500."""
    http, root = client
    answer = post(http, 0, encode_batch(_with_nulls(batch(0), "tool_x"), 0))
    assert answer.status_code == 422 and "tool_x is declared non-null" in answer.json()["error"]
    assert post(http, 0, encode_batch(batch(0), 0)).status_code == 200
    closed = http.post("/api/sessions/s1/close", json=CLOSE, headers=AUTH)
    assert closed.status_code == 200 and closed.json()["rows"]["samples"] == 100
    assert open_session(root / "station-a" / "s1").samples.num_rows == 100


def test_a_null_triangle_in_an_events_batch_is_refused(client):
    http, _ = client
    record = events((0.1, "contact_start"), (0.2, "contact_end"), (0.3, "pierce"))
    answer = post(http, 0, encode_batch(_with_nulls(record, "triangle"), 0), stream="events")
    assert answer.status_code == 422 and "triangle is declared non-null" in answer.json()["error"]
    assert EVENT_SCHEMA.field("triangle").nullable is False


def test_time_backwards_inside_a_batch_is_refused(client):
    http, _ = client
    record = batch(0)
    times = record.column("time").to_numpy().copy()
    times[[10, 11]] = times[[11, 10]]
    index = record.schema.get_field_index("time")
    swapped = record.set_column(index, record.schema.field("time"), pa.array(times))
    answer = post(http, 0, encode_batch(swapped, 0))
    assert answer.status_code == 422 and "time goes backwards inside the batch" in answer.json()["error"]


def test_a_resent_sequence_with_other_content_is_a_conflict_also_after_a_restart(tmp_path):
    """Seen: a re-sent sequence number with different content was answered "duplicate" and dropped."""
    store = IngestStore(tmp_path, TOKENS)
    http = TestClient(create_app(store))
    assert post(http, 0, encode_batch(batch(0), 0)).status_code == 200
    assert post(http, 0, encode_batch(batch(0), 0)).json()["duplicate"] is True
    other = post(http, 0, encode_batch(batch(7), 0))
    assert other.status_code == 409 and "already stored with different content" in other.json()["error"]
    store.close()
    store = IngestStore(tmp_path, TOKENS)  # the journal is read back: the digests with it
    http = TestClient(create_app(store))
    assert post(http, 0, encode_batch(batch(7), 0)).status_code == 409
    assert post(http, 0, encode_batch(batch(0), 0)).json()["duplicate"] is True
    assert http.post("/api/sessions/s1/close", json=CLOSE, headers=AUTH).status_code == 200
    assert post(http, 0, encode_batch(batch(7), 0)).status_code == 409  # after the close too
    store.close()
    store = IngestStore(tmp_path, TOKENS)  # and after a restart of the closed session (journals gone)
    http = TestClient(create_app(store))
    assert post(http, 0, encode_batch(batch(7), 0)).status_code == 409
    assert post(http, 0, encode_batch(batch(0), 0)).json()["duplicate"] is True
    xs = open_session(tmp_path / "station-a" / "s1").samples.column("tool_x").to_numpy()
    np.testing.assert_array_equal(xs, np.arange(100))
    store.close()


def test_a_second_header_does_not_replace_the_first(client):
    """Seen: a second header PUT silently replaced the first."""
    http, root = client
    first = {"participant": "T01", "task": "wall-stitch"}
    assert http.put("/api/sessions/s1/header", json=first, headers=AUTH).json() == {"header": True}
    again = http.put("/api/sessions/s1/header", json=first, headers=AUTH)
    assert again.status_code == 200 and again.json()["duplicate"] is True
    changed = http.put("/api/sessions/s1/header", json={**first, "participant": "T02"}, headers=AUTH)
    assert changed.status_code == 409 and "already has a header" in changed.json()["error"]
    stored = json.loads((root / "station-a" / "s1" / "header.json").read_text())
    assert stored["participant"] == "T01"


@pytest.mark.parametrize("text", ['{"participant": NaN}', '{"skill": Infinity}', '{"a": [1, -Infinity]}'])
def test_nan_never_reaches_stored_json(client, text):
    http, root = client
    answer = http.put("/api/sessions/s1/header", content=text.encode(), headers=AUTH)
    assert answer.status_code == 422 and "not a JSON number" in answer.json()["error"]
    stored = root / "station-a" / "s1" / "header.json"
    assert not stored.exists() or "NaN" not in stored.read_text()  # refused before anything is written


def test_routing_errors_use_the_json_error_shape(client):
    """Seen: 405 and routing errors answered in plain text."""
    http, _ = client
    wrong_method = http.get("/api/sessions/s1/close", headers=AUTH)
    assert wrong_method.status_code == 405 and wrong_method.headers["allow"] == "POST"
    assert set(wrong_method.json()) == {"error"}
    missing = http.get("/api/nothing-here", headers=AUTH)
    assert missing.status_code == 404 and set(missing.json()) == {"error"}


def test_a_damaged_central_journal_is_cut_at_the_damage_on_restart(tmp_path):
    """Issue 23 (3) on the central recorder: a batch damaged on disk while the server was down is cut
    with everything after it; the station re-sends from there and the session closes clean."""
    store = IngestStore(tmp_path, TOKENS)
    http = TestClient(create_app(store))
    for sequence in range(3):
        assert post(http, sequence, encode_batch(batch(100 * sequence), sequence)).status_code == 200
    store.close()
    journal = tmp_path / "station-a" / "s1" / "samples.arrows"
    data = bytearray(journal.read_bytes())
    data[len(data) * 3 // 5] ^= 0x10  # inside the second of three batches
    journal.write_bytes(bytes(data))
    store = IngestStore(tmp_path, TOKENS)
    http = TestClient(create_app(store))
    resent = [post(http, s, encode_batch(batch(100 * s), s)).json() for s in range(3)]
    assert resent[0]["duplicate"] is True and all(not r.get("duplicate") for r in resent[1:]), resent
    close = {"batches": {"samples": 3, "events": 0}, "status": "complete"}
    assert http.post("/api/sessions/s1/close", json=close, headers=AUTH).status_code == 200
    xs = open_session(tmp_path / "station-a" / "s1").samples.column("tool_x").to_numpy()
    np.testing.assert_array_equal(xs, np.arange(300))
    store.close()
