"""The recorder: round trips, crash recovery by kill -9, overflow accounting, bad files."""

import json
import os
import random
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import duckdb
import numpy as np
import pyarrow.parquet as pq
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from recorder import (
    COLUMN,
    SAMPLE_COLUMNS,
    RecorderError,
    SessionWriter,
    list_sessions,
    open_session,
    recover,
)
from recorder.writer import TRANSPOSE_BLOCK_ROWS, columns_of


def rows(n, start=0):
    data = np.zeros((n, len(SAMPLE_COLUMNS)))
    t = (np.arange(start, start + n)) * 1e-3
    data[:, COLUMN["time"]] = t
    data[:, COLUMN["tool_x"]] = np.sin(t)
    data[:, COLUMN["force_z"]] = np.cos(t) * 0.1
    data[:, COLUMN["contact_triangle"]] = np.where(np.arange(n) % 7 == 0, 12, -1)
    data[:, COLUMN["pierced"]] = np.arange(n) % 4
    data[:, COLUMN["tool_qw"]] = 1.0
    return data


def test_round_trip_bit_for_bit_and_in_three_engines(tmp_path):
    session = tmp_path / "s1"
    writer = SessionWriter(session, {"participant": "P01", "task": "arteriotomy"}, flush_interval=0.02)
    data = rows(20000)
    for row in data:
        assert writer.record(row)
    writer.event(
        0.5, "pierce", triangle=12, barycentric=(0.2, 0.3, 0.5), entry_angle_deg=4.0, tip_speed=0.003
    )
    writer.event(1.0, "marker", detail="supervisor note")
    header = writer.close()
    assert header["status"] == "complete" and header["samples"]["rows"] == 20000
    assert not (session / "samples.arrows").exists()
    loaded = open_session(session)
    for i, name in enumerate(SAMPLE_COLUMNS):
        np.testing.assert_array_equal(
            loaded.samples.column(name).to_numpy(),
            data[:, i].astype(loaded.samples.column(name).to_numpy().dtype),
        )
    assert loaded.events.column("kind").to_pylist() == ["pierce", "marker"]
    assert loaded.header["participant"] == "P01"
    frame = loaded.samples_frame("pandas")
    assert frame["force_z"].iloc[100] == pytest.approx(np.cos(0.1) * 0.1)
    assert loaded.samples_frame("polars").height == 20000
    count = duckdb.sql(
        f"select count(*) from '{session / 'samples.parquet'}' where contact_triangle = 12"
    ).fetchone()
    assert count[0] == (20000 + 6) // 7
    units = pq.read_schema(session / "samples.parquet").field("force_z").metadata[b"unit"]
    assert units == b"N"


def test_overflow_is_counted_and_recorded(tmp_path):
    writer = SessionWriter(tmp_path / "s", {}, flush_interval=10.0, capacity=1000)
    accepted = sum(writer.record(row) for row in rows(1500))
    assert accepted == 1000
    header = writer.close()
    session = open_session(tmp_path / "s")
    overflow = [r for r in session.events.to_pylist() if r["kind"] == "queue_overflow"]
    assert len(overflow) == 1 and "500 samples dropped between 1.000 s and 1.499 s" in overflow[0]["detail"]
    assert header["dropped_samples"] == 500


def test_events_reported_late_are_finished_in_time_order(tmp_path):
    """A real-time session's haptic process reports its safety events when the run ends, with the
    times they happened: the journal holds them as they came, the finished file in time order (one
    time keeping its order)."""
    writer = SessionWriter(tmp_path / "s", {}, flush_interval=0.01)
    for time_, kind in ((0.5, "contact_start"), (0.9, "pierce"), (0.2, "force_clamped"), (0.9, "exit")):
        writer.event(time_, kind)
    writer.close()
    events = open_session(tmp_path / "s").events
    assert events.column("time").to_pylist() == [0.2, 0.5, 0.9, 0.9]
    assert events.column("kind").to_pylist() == ["force_clamped", "contact_start", "pierce", "exit"]


CHILD = textwrap.dedent("""
    import sys, time, numpy as np
    from recorder import SessionWriter, COLUMN, SAMPLE_COLUMNS
    path, ack = sys.argv[1], sys.argv[2]
    writer = SessionWriter(path, {"participant": "crash"}, flush_interval=0.02)
    row = np.zeros(len(SAMPLE_COLUMNS))
    acked = 0
    with open(ack, "w") as log:
        i = 0
        while True:
            row[COLUMN["time"]] = i * 1e-3
            row[COLUMN["tool_x"]] = i
            writer.record(row)
            i += 1
            if writer.durable_samples != acked:
                acked = writer.durable_samples
                log.write(f"{acked}\\n"); log.flush()
            if i % 50 == 0:
                time.sleep(0.001)
""")


@pytest.mark.slow
def test_kill_9_loses_at_most_the_unflushed_tail(tmp_path):
    rng = random.Random(4)
    for attempt in range(8):
        session, ack = tmp_path / f"crash{attempt}", tmp_path / f"ack{attempt}"
        child = subprocess.Popen([sys.executable, "-c", CHILD, str(session), str(ack)])
        deadline = time.monotonic() + 60
        while not (ack.exists() and ack.read_text().strip()) and time.monotonic() < deadline:
            time.sleep(0.01)  # wait until the recorder is running
        time.sleep(rng.uniform(0.0, 0.6))
        os.kill(child.pid, signal.SIGKILL)
        child.wait()
        acknowledged = [int(x) for x in ack.read_text().split()] if ack.exists() else []
        header = recover(session)
        assert header["status"] == "recovered"
        recovered = open_session(session)
        xs = recovered.samples.column("tool_x").to_numpy()
        np.testing.assert_array_equal(xs, np.arange(len(xs)))  # contiguous, uncorrupted
        if acknowledged:
            assert len(xs) >= acknowledged[-1]  # everything acknowledged as durable is there
        if len(xs):
            assert recovered.header["recovered_until_s"] == pytest.approx((len(xs) - 1) * 1e-3)


def test_truncated_journal_recovers_complete_batches(tmp_path):
    session = tmp_path / "s"
    writer = SessionWriter(session, {}, flush_interval=10.0)
    for chunk in range(5):
        for row in rows(100, start=100 * chunk):
            writer.record(row)
        writer.flush()
    writer._stop.set()  # simulate a crash: no close(), no end-of-stream marker
    writer._thread.join()
    writer._sample_sink.close()
    writer._event_sink.close()
    journal = session / "samples.arrows"
    journal.write_bytes(journal.read_bytes()[:-37])  # power loss tears the last batch...
    Path(writer.header["ring"]["file"]).unlink()  # ...and takes the ring (tmpfs) with it
    header = recover(session)
    assert header["samples"]["rows"] == 400 and header["samples"]["torn_tail_cut"]
    assert header["samples"]["cut"]["after_batches"] == 4 and header["samples"]["cut"]["bytes"] > 0
    assert header["durable_until_s"] == header["recovered_until_s"] == pytest.approx(0.399)
    assert header["lost_at_most_s"] is None and "unknown" in header["loss_note"]  # never a constant


def test_a_dead_process_loses_nothing_it_recorded(tmp_path):
    """The journal's torn batch is cut, and every row after the last verified batch comes back from
    the ring the process left on tmpfs; the header says how long the unflushed stretch was."""
    session = tmp_path / "s"
    writer = SessionWriter(session, {}, flush_interval=10.0)
    for chunk in range(5):
        for row in rows(100, start=100 * chunk):
            writer.record(row)
        if chunk < 3:
            writer.flush()
    writer._stop.set()  # a crash: rows 300-499 recorded, never flushed
    writer._thread.join()
    writer._sample_sink.close()
    writer._event_sink.close()
    ring = Path(writer.header["ring"]["file"])
    header = recover(session)
    assert header["samples"]["rows"] == 500 and header["salvaged_samples"] == 200
    assert header["durable_until_s"] == pytest.approx(0.299)
    assert header["recovered_until_s"] == pytest.approx(0.499)
    assert header["unflushed_s"] == pytest.approx(0.2) and header["lost_at_most_s"] == 0.0
    np.testing.assert_array_equal(
        open_session(session).samples.column("tool_x").to_numpy(), np.sin(np.arange(500) * 1e-3)
    )
    assert not ring.exists()  # released once its rows are in the session


def test_a_ring_that_is_not_this_sessions_is_not_used(tmp_path):
    session = tmp_path / "s"
    writer = SessionWriter(session, {}, flush_interval=10.0)
    for row in rows(100):
        writer.record(row)
    writer.flush()
    for row in rows(50, start=100):
        writer.record(row)
    writer._stop.set()
    writer._thread.join()
    writer._sample_sink.close()
    writer._event_sink.close()
    ring = Path(writer.header["ring"]["file"])
    cells = np.fromfile(ring)
    cells[99 * len(SAMPLE_COLUMNS) + 1] += 1.0  # its copy of the journal's last row differs
    cells.tofile(ring)
    header = recover(session)
    assert header["samples"]["rows"] == 100 and header["lost_at_most_s"] is None
    assert "differs" in header["loss_note"]


def test_bad_files_are_named_and_do_not_hide_others(tmp_path):
    good = tmp_path / "good"
    writer = SessionWriter(good, {})
    for row in rows(100):
        writer.record(row)
    writer.close()
    flipped = tmp_path / "flipped"
    writer = SessionWriter(flipped, {})
    for row in rows(100):
        writer.record(row)
    writer.close()
    raw = bytearray((flipped / "samples.parquet").read_bytes())
    raw[len(raw) // 2] ^= 0x40
    (flipped / "samples.parquet").write_bytes(bytes(raw))
    with pytest.raises(RecorderError, match="does not match its recorded SHA-256"):
        open_session(flipped)
    future = tmp_path / "future"
    future.mkdir()
    (future / "header.json").write_text(json.dumps({"schema_version": 99, "status": "complete"}))
    with pytest.raises(RecorderError, match="schema version 99 is not one this vascsim reads"):
        open_session(future)
    truncated = tmp_path / "truncated"
    writer = SessionWriter(truncated, {})
    for row in rows(100):
        writer.record(row)
    writer.close()
    data = (truncated / "samples.parquet").read_bytes()
    (truncated / "samples.parquet").write_bytes(data[: len(data) // 2])
    with pytest.raises(RecorderError, match=r"cannot be read|does not match"):
        open_session(truncated)
    sessions, problems = list_sessions(tmp_path)
    assert [s.path.name for s in sessions] == ["good"]
    assert set(p.name for p in problems) == {"flipped", "future", "truncated"}
    with pytest.raises(RecorderError, match="already holds a recording"):
        SessionWriter(good, {})


def test_time_going_backwards_is_rejected(tmp_path):
    writer = SessionWriter(tmp_path / "s", {})
    data = rows(10)
    data[5, COLUMN["time"]] = 0.0001
    for row in data:
        writer.record(row)
    writer.close()
    with pytest.raises(RecorderError, match="time goes backwards at row 5"):
        open_session(tmp_path / "s")


def test_record_block_wraps_around_the_ring(tmp_path):
    writer = SessionWriter(tmp_path / "s", {}, flush_interval=10.0, capacity=100)
    data = rows(250)
    assert writer.record_block(data[:60]) == 60
    writer.flush()
    assert writer.record_block(data[60:160]) == 100  # wraps: 40 at the end, 60 from the start
    assert writer.record_block(data[160:170]) == 0  # full until flushed
    writer.flush()
    assert writer.record_block(data[160:250]) == 90
    writer.close()
    times = open_session(tmp_path / "s").samples.column("time").to_numpy()
    np.testing.assert_array_equal(times, data[:, COLUMN["time"]])


def test_record_takes_any_row_numpy_can_convert_and_names_a_wrong_length(tmp_path):
    """The fast path copies a contiguous float64 row; lists, other dtypes and strided rows take
    numpy's conversion; all are stored exactly; a row of the wrong length is refused."""
    writer = SessionWriter(tmp_path / "s", {}, flush_interval=10.0, capacity=16)
    data = rows(4)
    assert writer.record(data[0])  # contiguous float64
    assert writer.record(data[1].tolist())  # a list
    assert writer.record(data[2].astype(np.float32))  # another dtype: stored as its float64 value
    data[2] = data[2].astype(np.float32)
    strided = np.repeat(data[3][:, None], 2, axis=1)[:, 0]  # a non-contiguous view
    assert not strided.flags.c_contiguous and writer.record(strided)
    with pytest.raises(ValueError):
        writer.record(np.zeros(len(SAMPLE_COLUMNS) + 1))
    writer.close()
    stored = open_session(tmp_path / "s").samples
    np.testing.assert_array_equal(stored.column("time").to_numpy(), data[:, COLUMN["time"]])
    np.testing.assert_array_equal(stored.column("tool_x").to_numpy(), data[:, COLUMN["tool_x"]])


def test_every_event_kind_the_simulator_emits_has_a_place_in_the_schema():
    from recorder.schema import EVENT_KINDS
    from sim.needle.interaction import EVENT_KINDS as NEEDLE_KINDS
    from sim.runtime.shared import EVENT_CODES as RUNTIME_KINDS

    assert set(NEEDLE_KINDS) <= set(EVENT_KINDS)
    assert set(RUNTIME_KINDS) <= set(EVENT_KINDS)


@given(
    n=st.integers(0, 3 * TRANSPOSE_BLOCK_ROWS + 7),
    width=st.integers(1, 40),
    seed=st.integers(0, 2**32 - 1),
)
@settings(max_examples=40, deadline=None)
def test_blocked_transpose_equals_the_plain_one(n, width, seed):
    data = np.random.default_rng(seed).normal(size=(n, width))
    columns = columns_of(data)
    assert columns.flags.c_contiguous and columns.shape == (width, n)
    np.testing.assert_array_equal(columns, data.T)
