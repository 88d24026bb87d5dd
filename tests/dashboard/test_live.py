"""Live view: journals read while they grow (torn writes included), streamed as server-sent events."""

from __future__ import annotations

import io
import json
import threading
import time

import httpx
import numpy as np
import pyarrow as pa
import pyarrow.ipc as ipc
from sqlalchemy import select, update

from dashboard.streams.live import JournalTail, sample_payload
from recorder.schema import COLUMN, SAMPLE_COLUMNS
from recorder.writer import SessionWriter, samples_batch
from sessions.catalog import now
from sessions.catalog.models import Participant, Session, Task
from tests.dashboard.conftest import PASSWORD, running_server


def _rows(start: int, count: int) -> np.ndarray:
    rows = np.zeros((count, len(SAMPLE_COLUMNS)))
    rows[:, COLUMN["time"]] = (start + np.arange(count)) * 1e-3
    rows[:, COLUMN["force_z"]] = 0.5
    rows[:, COLUMN["tip_speed"]] = 0.004
    rows[:, COLUMN["local_stress"]] = np.nan
    return rows


def test_journal_tail_reads_only_complete_messages(tmp_path):
    sink = io.BytesIO()
    with ipc.new_stream(sink, samples_batch(_rows(0, 1)).schema) as writer:
        for k in range(4):
            writer.write_batch(samples_batch(_rows(100 * k, 100)))
    data = sink.getvalue()
    path = tmp_path / "samples.arrows"
    tail = JournalTail(path)
    assert tail.read_new() == []  # no file yet
    cut = len(data) // 2 + 7  # a torn write in the middle of a batch
    path.write_bytes(data[:cut])
    first = tail.read_new()
    assert 0 < sum(b.num_rows for b in first) < 400
    assert tail.read_new() == []  # nothing new is complete yet
    with open(path, "ab") as growing:
        growing.write(data[cut:])
    rest = tail.read_new()
    times = pa.Table.from_batches(first + rest).column("time").to_numpy()
    np.testing.assert_array_equal(times, np.arange(400) * 1e-3)


def test_sample_payload_decimates_across_calls():
    batch = samples_batch(_rows(0, 1000))  # 1 s at 1 kHz
    payload, last = sample_payload([batch.slice(0, 500)], 50.0, -np.inf)
    more, _ = sample_payload([batch.slice(500)], 50.0, last)
    times = np.array(payload["time"] + more["time"])
    assert len(times) == 50 and np.all(np.diff(times) > 0.019)
    assert payload["force"][0] == 500.0 and payload["tip_speed"][0] == 4.0 and payload["stress"][0] is None


def _running_session(seeded, directory) -> str:
    with seeded.catalog.session() as orm:
        participant = orm.get(Participant, seeded.own_participant)
        task = orm.scalar(select(Task))
        orm.add(
            Session(
                uid="LIVE-1",
                participant_id=participant.id,
                task_id=task.id,
                device="scripted",
                clock="realtime",
                trial=99,
                phase="practice",
                status="running",
                started_at=now(),
                directory=str(directory),
                error="",
            )
        )
    return "LIVE-1"


def test_live_view_streams_a_recording_session_until_it_stops(seeded):
    directory = seeded.home / "sessions" / "LIVE-1"
    uid = _running_session(seeded, directory)
    writer = SessionWriter(directory, {"session_id": uid}, flush_interval=0.05)
    stop = threading.Event()

    def station():
        k = 0
        while not stop.is_set():
            writer.record_block(_rows(k, 20))
            k += 20
            if k == 400:
                writer.event(0.4, "marker", detail="pierce here")
            time.sleep(0.02)

    recording = threading.Thread(target=station)
    recording.start()
    received, events, ended = 0, [], None
    try:
        with running_server(seeded.app) as base, httpx.Client(base_url=base, timeout=30) as client:
            client.post(
                "/api/login", json={"username": "supervisor", "password": PASSWORD}
            ).raise_for_status()
            with client.stream("GET", f"/api/live/sessions/{uid}") as stream:
                assert stream.headers["content-type"].startswith("text/event-stream")
                kind = None
                for line in stream.iter_lines():
                    if line.startswith("event: "):
                        kind = line[len("event: ") :]
                    elif line.startswith("data: "):
                        data = json.loads(line[len("data: ") :])
                        if kind == "samples":
                            received += len(data["time"])
                        elif kind == "event":
                            events.append(data)
                        elif kind == "end":
                            ended = data
                            break
                        if received >= 60 and events and not stop.is_set():
                            stop.set()  # the station stops: the catalog marks the session complete
                            recording.join()
                            writer.close()
                            with seeded.catalog.session() as orm:
                                orm.execute(
                                    update(Session).where(Session.uid == uid).values(status="complete")
                                )
    finally:
        stop.set()
        recording.join()
    assert received >= 60
    assert events[0]["kind"] == "marker" and events[0]["time"] == 0.4
    assert ended == {"reason": "the session is no longer recording"}


def test_live_view_refuses_sessions_that_are_not_recording(seeded, client_for):
    client, _ = client_for("supervisor")
    answer = client.get(f"/api/live/sessions/{seeded.own_sessions[0]}")
    assert answer.status_code == 409 and "not recording" in answer.json()["error"]["message"]
