"""Remote stations against the real ingest app: errors, exactly-once, a server killed mid-stream."""

import os
import signal
import socket
import subprocess
import sys
import time

import numpy as np
import pytest
from starlette.testclient import TestClient

from recorder import COLUMN, SAMPLE_COLUMNS, open_session, recover
from recorder.remote import IngestStore, StationUploader, create_app, encode_batch
from recorder.writer import samples_batch

TOKENS = {"secret-station-a": "station-a"}


def batch(start, n=100):
    rows = np.zeros((n, len(SAMPLE_COLUMNS)))
    rows[:, COLUMN["time"]] = (start + np.arange(n)) * 1e-3
    rows[:, COLUMN["tool_x"]] = start + np.arange(n)
    return samples_batch(rows)


def post(client, sequence, body, token="secret-station-a", session="s1"):
    return client.post(
        f"/api/sessions/{session}/batches/{sequence}",
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
    good = encode_batch(batch(0))
    assert post(client, 0, good, token="wrong").status_code == 401
    assert "token" in post(client, 0, good, token="wrong").json()["error"]
    assert post(client, 0, b"\x00garbage").status_code == 422
    nan = batch(0)
    times = nan.column("time").to_numpy().copy()
    times[3] = np.nan
    import pyarrow as pa

    nan = nan.set_column(0, nan.schema.field("time"), pa.array(times))
    assert "finite" in post(client, 0, encode_batch(nan)).json()["error"]
    other = batch(0).replace_schema_metadata({b"vascsim.schema_version": b"99"})
    assert "unknown schema version" in post(client, 0, encode_batch(other)).json()["error"]
    assert post(client, 5, good).status_code == 409  # gap: 0 expected
    assert (
        not (tmp_path / "station-a" / "s1" / "samples.arrows").exists()
        or (tmp_path / "station-a" / "s1" / "samples.arrows").stat().st_size < 2000
    )
    assert post(client, 0, good).json() == {"ack": 0, "duplicate": False}
    assert post(client, 0, good).json() == {"ack": 0, "duplicate": True}
    assert post(client, 1, encode_batch(batch(50))).status_code == 409  # goes back in time
    assert post(client, 1, encode_batch(batch(100))).status_code == 200


def test_exactly_once_across_a_store_restart(tmp_path, stores):
    first = stores(tmp_path)
    client = TestClient(create_app(first))
    bodies = [encode_batch(batch(100 * k)) for k in range(6)]
    for k in range(4):
        assert post(client, k, bodies[k]).status_code == 200
    first.close()
    restarted = TestClient(create_app(stores(tmp_path)))  # the journal is the truth
    for k, body in enumerate(bodies):  # the station sends everything again
        assert post(restarted, k, body).status_code == 200
    recover(tmp_path / "station-a" / "s1")
    xs = open_session(tmp_path / "station-a" / "s1").samples.column("tool_x").to_numpy()
    np.testing.assert_array_equal(xs, np.arange(600))


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


SERVER = """
import sys, uvicorn
from recorder.remote import IngestStore, create_app
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
def test_station_survives_a_server_killed_mid_stream(tmp_path):
    port = free_port()
    server = start_server(tmp_path / "central", port)
    station = StationUploader(f"http://127.0.0.1:{port}", "secret-station-a", "s2", tmp_path / "spool")
    try:
        for k in range(10):
            station.submit(batch(100 * k))
            station.send_pending()
        os.kill(server.pid, signal.SIGKILL)  # the central recorder dies
        server.wait()
        for k in range(10, 20):
            station.submit(batch(100 * k))
            assert station.send_pending() == 0  # link down: kept in the spool
        assert len(list((tmp_path / "spool").glob("*.batch"))) == 10
        server = start_server(tmp_path / "central", port)
        assert station.send_pending() == 10
        assert not list((tmp_path / "spool").glob("*.batch"))
    finally:
        station.close()
        server.kill()
        server.wait()
    recover(tmp_path / "central" / "station-a" / "s2")
    xs = open_session(tmp_path / "central" / "station-a" / "s2").samples.column("tool_x").to_numpy()
    np.testing.assert_array_equal(xs, np.arange(2000))  # every sample, once, in order
