"""Issue 23 part 5: SessionWriter's public methods from several threads at once."""

import threading

import numpy as np
import pytest

from recorder import SessionWriter, open_session
from recorder.schema import SAMPLE_COLUMNS, RecorderError

ROWS = 30_000


def rows(start: int, count: int) -> np.ndarray:
    block = np.zeros((count, len(SAMPLE_COLUMNS)))
    block[:, 0] = (start + np.arange(count)) * 1e-3
    block[:, SAMPLE_COLUMNS.index("reaction_x")] = 0.0
    return block


@pytest.mark.parametrize("run", range(12))
def test_flush_from_another_thread_while_blocks_are_recorded_loses_and_repeats_nothing(tmp_path, run):
    writer = SessionWriter(tmp_path / "s", {"session_id": "s"}, flush_interval=0.002, capacity=4096)
    stop = threading.Event()

    def flusher():
        while not stop.is_set():
            writer.flush()

    threads = [threading.Thread(target=flusher) for _ in range(2)]
    for thread in threads:
        thread.start()
    sent = 0
    while sent < ROWS:
        sent += writer.record_block(rows(sent, min(700, ROWS - sent)))
    stop.set()
    for thread in threads:
        thread.join()
    writer.close()
    time = open_session(tmp_path / "s").samples.column("time").to_numpy()
    assert len(time) == ROWS
    np.testing.assert_array_equal(time, np.arange(ROWS) * 1e-3)


def test_a_closed_writer_refuses_clearly(tmp_path):
    writer = SessionWriter(tmp_path / "s", {"session_id": "s"})
    writer.record_block(rows(0, 10))
    writer.close()
    with pytest.raises(RecorderError, match="closed"):
        writer.flush()
    with pytest.raises(RecorderError, match="closed"):
        writer.record_block(rows(10, 1))
    with pytest.raises(RecorderError, match="closed"):
        writer.close()
