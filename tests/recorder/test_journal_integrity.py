"""Recovery never launders damage (issue 23, parts 3, 4 and 7): every journal batch carries its
checksum, recovery keeps the verified prefix and says what it cut, a failed recovery leaves
nothing behind, and a process killed before its first flush loses nothing it recorded."""

import os
import random
import shutil
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from recorder import COLUMN, SAMPLE_COLUMNS, RecorderError, SessionWriter, open_session, recover
from recorder.integrity import CHECKSUM_KEY, scan_journal
from recorder.schema import SAMPLE_SCHEMA

BATCHES, ROWS = 10, 100


def crashed_session(folder: Path) -> Path:
    """A session killed after ten flushed batches of 100 rows (tool_x = row index); no ring."""
    writer = SessionWriter(folder, {}, flush_interval=10.0)
    for batch in range(BATCHES):
        data = np.zeros((ROWS, len(SAMPLE_COLUMNS)))
        index = np.arange(batch * ROWS, (batch + 1) * ROWS)
        data[:, COLUMN["time"]] = index * 1e-3
        data[:, COLUMN["tool_x"]] = index
        data[:, COLUMN["force_z"]] = np.sin(index)
        data[:, COLUMN["tool_qw"]] = 1.0
        data[:, COLUMN["contact_triangle"]] = -1
        writer.record_block(data)
        writer.flush()
    writer._stop.set()
    writer._thread.join()
    writer._sample_sink.close()
    writer._event_sink.close()
    Path(writer.header["ring"]["file"]).unlink()  # the machine went down: only the journal is left
    return folder


def test_every_journal_batch_carries_a_checksum_that_verifies(tmp_path):
    session = crashed_session(tmp_path / "s")
    scan = scan_journal(session / "samples.arrows", SAMPLE_SCHEMA, require_checksums=True)
    assert len(scan.batches) == BATCHES and scan.problem is None
    assert all(CHECKSUM_KEY in metadata for metadata in scan.metadata)


@pytest.mark.slow
def test_sixty_bit_flips_never_recover_an_altered_value(tmp_path):
    """Each flip in its own copy of the crashed session: recovery either stops before the damaged
    batch (saying so) or refuses the journal; every value it keeps is the value recorded."""
    original = crashed_session(tmp_path / "original")
    size = (original / "samples.arrows").stat().st_size
    rng = random.Random(23)
    accepted_altered, cut_or_refused = 0, 0
    for flip in range(60):
        copy = tmp_path / f"flip{flip}"
        shutil.copytree(original, copy)
        journal = copy / "samples.arrows"
        data = bytearray(journal.read_bytes())
        position = rng.randrange(size)
        data[position] ^= 1 << rng.randrange(8)
        journal.write_bytes(bytes(data))
        try:
            header = recover(copy)
        except RecorderError as error:  # the journal's schema message itself was hit
            assert "schema" in str(error) or "unreadable" in str(error)
            assert not (copy / "samples.parquet").exists()
            cut_or_refused += 1
            continue
        kept = open_session(copy).samples
        x = kept.column("tool_x").to_numpy()
        force = kept.column("force_z").to_numpy()
        altered = not (
            np.array_equal(x, np.arange(len(x))) and np.array_equal(force, np.sin(np.arange(len(x))))
        )
        accepted_altered += altered
        if len(x) < BATCHES * ROWS:
            cut_or_refused += 1
            assert header["samples"]["cut"]["after_batches"] == len(x) // ROWS
            assert header["samples"]["cut"]["bytes"] > 0 and header["samples"]["cut"]["reason"]
    assert accepted_altered == 0
    assert cut_or_refused >= 55  # flips in Arrow's padding change no value and need no cut


def test_a_failed_recovery_leaves_no_parquet_behind(tmp_path):
    session = crashed_session(tmp_path / "s")
    shutil.copy(session / "samples.arrows", session / "events.arrows")  # another stream's journal
    with pytest.raises(RecorderError, match=r"events\.arrows does not hold the events schema"):
        recover(session)
    assert sorted(p.name for p in session.iterdir()) == ["events.arrows", "header.json", "samples.arrows"]


def test_an_unreadable_events_journal_is_cut_and_said_so(tmp_path):
    session = crashed_session(tmp_path / "s")
    (session / "events.arrows").write_bytes(b"\xff" * 64)
    header = recover(session)
    assert header["samples"]["rows"] == BATCHES * ROWS and not header["samples"]["torn_tail_cut"]
    assert header["events"]["rows"] == 0 and "unreadable" in header["events"]["cut"]["reason"]


def test_a_missing_journal_is_named(tmp_path):
    session = crashed_session(tmp_path / "s")
    (session / "events.arrows").unlink()
    with pytest.raises(RecorderError, match=r"events\.arrows is missing"):
        recover(session)
    assert not (session / "samples.parquet").exists()


CHILD = textwrap.dedent("""
    import sys, time, numpy as np
    from recorder import SessionWriter, COLUMN, SAMPLE_COLUMNS
    path, started = sys.argv[1], sys.argv[2]
    writer = SessionWriter(path, {"participant": "crash"}, flush_interval=0.1)
    row = np.zeros(len(SAMPLE_COLUMNS))
    t0 = time.monotonic()
    with open(started, "w") as note:
        note.write(repr(t0))
    i = 0
    while True:  # 1 kHz, paced on the monotonic clock the parent reads too
        row[COLUMN["time"]] = i * 1e-3
        row[COLUMN["tool_x"]] = i
        writer.record(row)
        i += 1
        pause = t0 + i * 1e-3 - time.monotonic()
        if pause > 0:
            time.sleep(pause)
""")


@pytest.mark.slow
def test_kills_from_the_first_sample_on_lose_nothing_recorded(tmp_path):
    """Killed 0-250 ms after recording starts (before, at and after the first flush): every
    sample up to the kill is recovered and the header's measured gap is what was unflushed."""
    rng = random.Random(7)
    for attempt in range(6):
        session, started = tmp_path / f"k{attempt}", tmp_path / f"t{attempt}"
        child = subprocess.Popen([sys.executable, "-c", CHILD, str(session), str(started)])
        deadline = time.monotonic() + 60
        while not (started.exists() and started.read_text()) and time.monotonic() < deadline:
            time.sleep(0.002)
        t0 = float(started.read_text())
        time.sleep(rng.uniform(0.0, 0.25))
        killed_at = time.monotonic()
        os.kill(child.pid, signal.SIGKILL)
        child.wait()
        header = recover(session)
        x = open_session(session).samples.column("tool_x").to_numpy()
        np.testing.assert_array_equal(x, np.arange(len(x)))  # contiguous from the first sample
        loss = (killed_at - t0) - (len(x) - 1) * 1e-3
        assert loss < 0.05  # a late tick at most (the ring kept every row the process recorded)
        assert header["lost_at_most_s"] == 0.0 and header["salvaged_samples"] >= 0
        durable = header["durable_until_s"]
        assert header["unflushed_s"] == pytest.approx(header["recovered_until_s"] - (durable or 0.0)) or (
            durable is None and header["unflushed_s"] is None
        )
