"""The recording's ring on tmpfs: where a writer's rows wait for the flush, and what a dead recording
process leaves there for :func:`recorder.finalize.recover` to salvage.

The ring is a shared mapping of ``capacity x width`` float64 cells followed by counters (rows written,
rows flushed, drops); in ``/dev/shm`` it outlives the process that wrote it, so the rows recorded
after the journal's last batch can be checked and kept.
"""

from __future__ import annotations

import math
import mmap
import os
import re
import uuid
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from recorder.batches import same_values, samples_batch
from recorder.schema import INTEGER_COLUMNS, SAMPLE_COLUMNS

RING_DIRECTORY = Path("/dev/shm")
"""Where a writer's ring lives as a file (tmpfs: memory, as fast as an anonymous mapping, and still
there after the recording process dies). Without it, or without room, the ring is anonymous."""


def ring_mapping(size: int) -> tuple[mmap.mmap, Path | None]:
    """A shared mapping of ``size`` bytes, and the tmpfs file behind it (None: anonymous)."""
    if RING_DIRECTORY.is_dir():
        path = RING_DIRECTORY / f"vascsim-ring-{uuid.uuid4().hex}"
        try:
            descriptor = os.open(path, os.O_RDWR | os.O_CREAT | os.O_EXCL, 0o600)
            try:
                os.posix_fallocate(descriptor, 0, size)  # no room: refused here, never a SIGBUS later
                return mmap.mmap(descriptor, size), path
            finally:
                os.close(descriptor)
        except OSError:
            path.unlink(missing_ok=True)
    return mmap.mmap(-1, size), None


HEAD, TAIL, DROPPED, FIRST_DROPPED, LAST_DROPPED = 0, 8, 16, 17, 18
"""Cells after the ring: rows written (producer), rows flushed (writer), and the drop count and
time range since the last flush. Head and tail sit 64 bytes apart, on cache lines of their own:
the producer's record() never misses on a line the writer has just written."""
COUNTER_CELLS = 24


_RING_NAME = re.compile(r"vascsim-ring-[0-9a-f]{32}")


def _ring_path(header: dict[str, Any]) -> Path | None:
    """The header's ring file, if it names one of ours (a header is data someone could edit)."""
    ring = header.get("ring")
    name = ring.get("file") if isinstance(ring, dict) else None
    if not isinstance(name, str):
        return None
    path = Path(name)
    return path if path.parent == RING_DIRECTORY and _RING_NAME.fullmatch(path.name) else None


def release_ring(header: dict[str, Any]) -> None:
    """Remove a session's ring file (after close or recovery: its rows are in the journal now)."""
    path = _ring_path(header)
    if path is not None:
        path.unlink(missing_ok=True)


def salvage_ring(
    header: dict[str, Any], durable: pa.Table
) -> tuple[pa.RecordBatch | None, dict[str, Any] | None, str | None]:
    """The rows a dead recording process had recorded after its journal's last verified batch.

    Returns (rows or None if there were none, the ring's counters, or None with the reason the
    ring could not be used). The ring is checked before anything is taken from it: our own file,
    the layout the header states, a row count that continues the journal without a gap, its
    copy of the journal's last row equal to that row, times that go on from the journal's.
    """
    path = _ring_path(header)
    ring = header.get("ring") if isinstance(header.get("ring"), dict) else {}
    if path is None:
        return None, None, "the ring was not kept in a file (no tmpfs at /dev/shm, or no room)"
    if not path.exists():
        return None, None, f"the ring file {path} is gone (the machine restarted?)"
    capacity, width = ring.get("capacity"), ring.get("width")
    if type(capacity) is not int or capacity < 1 or width != len(SAMPLE_COLUMNS):
        return None, None, f"the header's ring layout {ring} is not one this vascsim writes"
    cells = np.fromfile(path, dtype=np.float64)
    if cells.size != capacity * width + COUNTER_CELLS:
        return None, None, f"the ring file {path} holds {cells.size} cells, not the header's layout"
    rows, counters = cells[: capacity * width].reshape(capacity, width), cells[capacity * width :]
    head, dropped, kept = counters[HEAD], counters[DROPPED], durable.num_rows
    if not (np.isfinite(head) and head == int(head) and kept <= head <= kept + capacity):
        return None, None, f"the ring's row count {head} does not continue the journal's {kept} rows"
    head = int(head)
    if kept and kept - 1 >= head - capacity:  # the ring still holds the journal's last row
        last = samples_batch(rows[(kept - 1) % capacity][None, :])
        if not same_values(pa.Table.from_batches([last]), durable.slice(kept - 1)):
            return None, None, "the ring's copy of the journal's last row differs (not this session's ring)"
    found = {"rows_recorded": head, "dropped_unflushed": int(dropped) if np.isfinite(dropped) else None}
    if head == kept:
        return None, found, None
    unflushed = rows[np.arange(kept, head) % capacity]
    times = unflushed[:, 0]
    start = durable.column("time")[-1].as_py() if kept else -math.inf
    if not np.isfinite(times).all() or np.any(np.diff(times) < 0) or times[0] < start:
        return None, None, "the ring's unflushed rows do not go on in time from the journal"
    codes = unflushed[:, [SAMPLE_COLUMNS.index(name) for name in INTEGER_COLUMNS]]
    if not (np.isfinite(codes).all() and np.array_equal(codes, np.round(codes))):
        return None, None, "the ring's unflushed rows hold codes that are not integers"
    batch = samples_batch(unflushed)
    return batch, found, None
