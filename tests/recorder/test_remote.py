"""Remote stations against the real ingest app and a real uvicorn server, over HTTP and WebSocket:
clear errors, header/events/close, exactly once across restarts and cut links."""

import json
import os
import signal
import socket
import subprocess
import sys
import time

import numpy as np
import pyarrow as pa
import pytest
from starlette.testclient import TestClient

from recorder import COLUMN, SAMPLE_COLUMNS, RecorderError, SessionWriter, open_session, recover
from recorder.remote.ingest import IngestStore
from recorder.remote.protocol import MAX_BATCH_BYTES, encode_batch, pack_frame
from recorder.remote.routes import create_app
from recorder.remote.station import StationUploader
from recorder.schema import EVENT_SCHEMA, SAMPLE_SCHEMA
from recorder.writer import read_journal, same_values, samples_batch

TOKENS = {"secret-station-a": "station-a"}
AUTH = {"Authorization": "Bearer secret-station-a"}


def batch(start, n=100):
    rows = np.zeros((n, len(SAMPLE_COLUMNS)))
    rows[:, COLUMN["time"]] = (start + np.arange(n)) * 1e-3
    rows[:, COLUMN["tool_x"]] = start + np.arange(n)
    return samples_batch(rows)


def events(*items):
    """An events batch of (time, kind) pairs."""
    n = len(items)
    columns = {
        "time": [t for t, _ in items],
        "kind": [k for _, k in items],
        "triangle": [-1] * n,
        **{
            name: [float("nan")] * n
            for name in ("bary_0", "bary_1", "bary_2", "entry_angle_deg", "tip_speed")
        },
        "layer": ["haptic"] * n,
        "detail": [""] * n,
    }
    return pa.RecordBatch.from_pydict(columns, schema=EVENT_SCHEMA)


def with_column(record, name, values):
    index = record.schema.get_field_index(name)
    return record.set_column(index, record.schema.field(name), pa.array(values))


def post(client, sequence, body, token="secret-station-a", session="s1", stream="samples"):
    return client.post(
        f"/api/sessions/{session}/{stream}/{sequence}",
        content=body,
        headers={"Authorization": f"Bearer {token}"},
    )


@pytest.fixture
def stores():
    made = []
    yield lambda root: made.append(IngestStore(root, TOKENS)) or made[-1]
    for store in made:
        store.close()


def test_bad_input_gets_clear_errors_and_writes_nothing(tmp_path, stores):
    client = TestClient(create_app(stores(tmp_path)))
    good = encode_batch(batch(0), 0)
    assert post(client, 0, good, token="wrong").status_code == 401
    assert "token" in post(client, 0, good, token="wrong").json()["error"]
    assert post(client, 0, b"\x00garbage").status_code == 422
    times = batch(0).column("time").to_numpy().copy()
    times[3] = np.nan
    assert (
        "time must be finite"
        in post(client, 0, encode_batch(with_column(batch(0), "time", times), 0)).json()["error"]
    )
    forces = np.zeros(100)
    forces[7] = np.inf
    answer = post(client, 0, encode_batch(with_column(batch(0), "force_z", forces), 0))
    assert answer.status_code == 422 and "force_z must be finite" in answer.json()["error"]
    other = batch(0).replace_schema_metadata({b"vascsim.schema_version": b"99"})
    assert "unknown schema version" in post(client, 0, encode_batch(other, 0)).json()["error"]
    assert post(client, 0, good, stream="video").status_code == 404
    assert post(client, "x1", good).status_code == 422
    too_big = post(client, 0, b"\x00" * (MAX_BATCH_BYTES + 1))
    assert too_big.status_code == 413 and "exceeds" in too_big.json()["error"]
    assert (
        "unknown event kind"
        in post(client, 0, encode_batch(events((0.1, "teleport")), 0), stream="events").json()["error"]
    )
    mislabelled = post(client, 5, good)  # the body says it is batch 0
    assert mislabelled.status_code == 422 and "says it is b'0'" in mislabelled.json()["error"]
    assert post(client, 5, encode_batch(batch(0), 5)).status_code == 409  # gap: 0 expected
    assert client.put("/api/sessions/s1/header", content=b"[1, 2]", headers=AUTH).status_code == 422
    assert client.put("/api/sessions/../header", content=b"{}", headers=AUTH).status_code in (404, 422)
    assert client.put("/api/sessions/a.b/header", content=b"{}", headers=AUTH).status_code == 422
    journal = tmp_path / "station-a" / "s1" / "samples.arrows"
    assert read_journal(journal, SAMPLE_SCHEMA) == (SAMPLE_SCHEMA.empty_table(), False)  # nothing got in
    assert post(client, 0, good).json() == {"stream": "samples", "ack": 0, "duplicate": False}
    assert post(client, 0, good).json() == {"stream": "samples", "ack": 0, "duplicate": True}
    back = post(client, 1, encode_batch(batch(50), 1))
    assert back.status_code == 409 and "goes back in time" in back.json()["error"]
    assert post(client, 1, encode_batch(batch(100), 1)).status_code == 200
    early = client.post("/api/sessions/s1/close", json={"batches": {"samples": 3, "events": 0}}, headers=AUTH)
    assert early.status_code == 409 and "server holds 2, station sent 3" in early.json()["error"]
    assert (
        client.post("/api/sessions/s1/close", json={"batches": {"samples": 2}}, headers=AUTH).status_code
        == 422
    )
    closing = {"batches": {"samples": 2, "events": 0}, "status": "complete"}
    closed = client.post("/api/sessions/s1/close", json=closing, headers=AUTH)
    assert closed.json() == {"closed": True, "duplicate": False, "rows": {"samples": 200, "events": 0}}
    assert client.post("/api/sessions/s1/close", json=closing, headers=AUTH).json()["duplicate"] is True
    assert post(client, 1, encode_batch(batch(100), 1)).json()["duplicate"] is True
    late = post(client, 2, encode_batch(batch(200), 2))
    assert late.status_code == 409 and "closed" in late.json()["error"]
    xs = open_session(tmp_path / "station-a" / "s1").samples.column("tool_x").to_numpy()
    np.testing.assert_array_equal(xs, np.arange(200))


def test_exactly_once_across_a_store_restart(tmp_path, stores):
    first = stores(tmp_path)
    client = TestClient(create_app(first))
    bodies = [encode_batch(batch(100 * k), k) for k in range(6)]
    for k in range(4):
        assert post(client, k, bodies[k]).status_code == 200
    first.close()
    restarted = TestClient(create_app(stores(tmp_path)))  # the journal is the truth
    for k, body in enumerate(bodies):  # the station sends everything again
        assert post(restarted, k, body).status_code == 200
    recover(tmp_path / "station-a" / "s1")
    xs = open_session(tmp_path / "station-a" / "s1").samples.column("tool_x").to_numpy()
    np.testing.assert_array_equal(xs, np.arange(600))


def test_websocket_frames_get_answers_in_order(tmp_path, stores):
    client = TestClient(create_app(stores(tmp_path)))
    with client.websocket_connect("/api/sessions/w1/ws", headers={"Authorization": "Bearer nope"}) as socket_:
        assert socket_.receive_json()["status"] == 401
    with client.websocket_connect("/api/sessions/w1/ws", headers=AUTH) as socket_:
        socket_.send_text(json.dumps({"op": "header", "header": {"participant": "P07", "task": "cube"}}))
        socket_.send_bytes(pack_frame("samples", 0, encode_batch(batch(0), 0)))
        socket_.send_bytes(pack_frame("samples", 0, encode_batch(batch(0), 0)))
        socket_.send_bytes(pack_frame("events", 0, encode_batch(events((0.05, "contact_start")), 0)))
        socket_.send_bytes(b"\x07" + bytes(8))
        socket_.send_bytes(b"\x00")
        socket_.send_text("not json")
        socket_.send_text(json.dumps({"op": "close", "batches": {"samples": 1, "events": 1}}))
        answers = [socket_.receive_json() for _ in range(8)]
    assert [a["status"] for a in answers] == [200, 200, 200, 200, 404, 422, 422, 200]
    assert answers[1]["duplicate"] is False and answers[2]["duplicate"] is True
    session = open_session(tmp_path / "station-a" / "w1")
    assert session.header["participant"] == "P07" and session.header["station"] == "station-a"
    assert session.samples.num_rows == 100
    assert session.events.column("kind").to_pylist() == ["contact_start"]


def test_a_station_that_leaves_before_its_answers_still_gets_everything_stored_once(tmp_path, stores):
    """Twenty batches sent and the connection closed without reading an answer: nothing is
    dropped half-way (every answer runs to its end, none is left unawaited), and sending all of
    them again on a new connection, as a station does with what it saw no acknowledgement for,
    stores each exactly once."""
    store = stores(tmp_path)
    client = TestClient(create_app(store))
    frames = [pack_frame("samples", k, encode_batch(batch(100 * k), k)) for k in range(20)]
    for attempt in range(3):
        with client.websocket_connect("/api/sessions/gone/ws", headers=AUTH) as socket_:
            for frame in frames:
                socket_.send_bytes(frame)
            if attempt == 2:
                answers = [socket_.receive_json() for _ in frames]
                socket_.send_text(json.dumps({"op": "close", "batches": {"samples": 20, "events": 0}}))
                closed = socket_.receive_json()
    assert [a["status"] for a in answers] == [200] * 20 and all(a["duplicate"] for a in answers)
    assert closed["status"] == 200
    xs = open_session(tmp_path / "station-a" / "gone").samples.column("tool_x").to_numpy()
    np.testing.assert_array_equal(xs, np.arange(2000))


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


SERVER = """
import sys, uvicorn
from recorder.remote.ingest import IngestStore
from recorder.remote.routes import create_app
uvicorn.run(create_app(IngestStore(sys.argv[1], {"secret-station-a": "station-a"})),
            host="127.0.0.1", port=int(sys.argv[2]), log_level="warning")
"""


def start_server(root, port):
    process = subprocess.Popen([sys.executable, "-c", SERVER, str(root), str(port)])
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
            return process
        except OSError:
            time.sleep(0.05)
    process.kill()
    raise RuntimeError("ingest server did not start")


@pytest.mark.slow
@pytest.mark.parametrize("transport", ["http", "websocket"])
def test_station_survives_a_server_killed_mid_stream(tmp_path, transport):
    port = free_port()
    server = start_server(tmp_path / "central", port)
    station = StationUploader(
        f"http://127.0.0.1:{port}", "secret-station-a", "s2", tmp_path / "spool", transport=transport
    )
    try:
        station.set_header({"participant": "P01", "task": "artery"})
        for k in range(10):
            station.submit("samples", batch(100 * k))
            station.send_pending()
        station.submit("events", events((0.2, "contact_start"), (0.4, "pierce")))
        os.kill(server.pid, signal.SIGKILL)  # the central recorder dies
        server.wait()
        for k in range(10, 20):
            station.submit("samples", batch(100 * k))
            assert station.send_pending() == 0  # link down: kept in the spool
        station.submit("events", events((1.5, "exit")))
        station.finish()
        assert station.pending == 13  # 10 sample batches, 2 event batches, the close request
        server = start_server(tmp_path / "central", port)
        assert station.send_pending() == 13
        assert station.pending == 0
        station.send_pending()  # sending again changes nothing
    finally:
        station.close()
        server.kill()
        server.wait()
    session = open_session(tmp_path / "central" / "station-a" / "s2")
    assert session.header["status"] == "complete" and session.header["participant"] == "P01"
    xs = session.samples.column("tool_x").to_numpy()
    np.testing.assert_array_equal(xs, np.arange(2000))  # every sample, once, in order
    assert session.events.column("kind").to_pylist() == ["contact_start", "pierce", "exit"]


@pytest.mark.slow
def test_a_recording_mirrored_to_the_central_recorder_equals_the_local_one(tmp_path):
    port = free_port()
    server = start_server(tmp_path / "central", port)
    station = StationUploader(
        f"http://127.0.0.1:{port}", "secret-station-a", "m1", tmp_path / "spool", transport="websocket"
    )
    try:
        header = {"participant": "P02", "task": "cube", "device": "scripted"}
        station.set_header(header)
        writer = SessionWriter(tmp_path / "local", header, flush_interval=0.02, mirror=station.submit)
        station.start(interval=0.02)
        data = batch(0, n=3000)
        rows = np.column_stack([c.to_numpy().astype(float) for c in data.columns])
        for k, row in enumerate(rows):
            writer.record(row)
            if k % 500 == 0:
                writer.event(row[0], "marker", detail=f"row {k}")
            if k % 100 == 0:
                time.sleep(0.002)
        writer.close()
        station.finish()
        station.stop(timeout=30)
    finally:
        station.close()
        server.kill()
        server.wait()
    local = open_session(tmp_path / "local")
    central = open_session(tmp_path / "central" / "station-a" / "m1")
    assert same_values(central.samples, local.samples) and central.samples.num_rows == 3000
    assert same_values(central.events, local.events) and central.events.num_rows == 6


def test_refused_items_stay_in_the_spool_and_are_named(tmp_path, stores):
    store = stores(tmp_path / "central")
    client = TestClient(create_app(store))
    station = StationUploader(
        "http://testserver", "secret-station-a", "r1", tmp_path / "spool", http_client=client
    )
    station.submit("samples", batch(100))
    station.submit("samples", batch(0))  # goes back in time
    with pytest.raises(RecorderError, match=r"refused samples batch 1 of session r1: 409 .*back in time"):
        station.send_pending()
    assert station.pending == 1 and (tmp_path / "spool" / "samples" / "000000000001.batch").exists()
    restarted = StationUploader("http://testserver", "secret-station-a", "r1", tmp_path / "spool")
    assert restarted.submit("samples", batch(200)) == 2  # numbering continues across restarts
