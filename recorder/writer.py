"""Durable session recording that never blocks the haptic loop.

``record(row)`` copies one sample row into a preallocated ring (a compiled push,
``recorder._ring``: well under a microsecond with warm caches, no locks, no
allocation) and returns; a background thread turns
the rows written since its last pass into an Arrow record batch, appends it to
an append-only journal (Arrow IPC stream, every batch with its own checksum:
:mod:`recorder.integrity`) and fsyncs it every ``flush_interval`` (100 ms by
default), so a machine crash loses at most that interval. The ring itself lives
in a file on tmpfs (``/dev/shm``) where there is room: if the recording process
dies, ``recover`` finds every sample it recorded there, flushed or not.
If the ring fills up (the disk stalls), samples are dropped and counted, and a
``queue_overflow`` event records how many and over which time range: nothing is
lost silently. ``close()`` turns the journals into Parquet (zstd), verifies them,
records their SHA-256 in ``header.json``, and only then removes the journals.

Everything a flush needs (imports, code paths, the journals' schemas) is loaded
and written when the writer is created, so the first flush is as quick as the
later ones: a writer is ready to record when its constructor returns.

Session directory: ``header.json``, ``samples.arrows`` / ``events.arrows``
(journals while recording), ``samples.parquet`` / ``events.parquet`` (after close).
"""

from __future__ import annotations

import math
import os
import threading
import time as clock
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.ipc as ipc
from numpy.typing import NDArray

from recorder._ring import RingProducer
from recorder.batches import (
    TRANSPOSE_BLOCK_ROWS,
    columns_of,
    events_batch,
    read_journal,
    same_values,
    samples_batch,
)
from recorder.finalize import finalize, recover
from recorder.integrity import CHECKSUM_NAME, sealed
from recorder.layout import (
    EVENTS_JOURNAL,
    HEADER_FILE,
    SAMPLES_FILE,
    SAMPLES_JOURNAL,
    sha256_of,
    write_json_atomically,
)
from recorder.ring import (
    COUNTER_CELLS,
    DROPPED,
    FIRST_DROPPED,
    HEAD,
    LAST_DROPPED,
    TAIL,
    release_ring,
    ring_mapping,
    salvage_ring,
)
from recorder.scene import write_scene
from recorder.schema import (
    EVENT_SCHEMA,
    SAMPLE_COLUMNS,
    SAMPLE_SCHEMA,
    SCHEMA_VERSION,
    RecorderError,
)


class SessionWriter:
    """Records one session into ``directory`` (see the module docstring).

    header: session metadata (participant, session ids, task, mesh hash,
        materials, model parameters, device, software version, clock mode, ...).
    mirror: called from the writer thread with ("samples" | "events", batch) for every batch
        once it is durable here, e.g. ``recorder.remote.station.StationUploader.submit`` to stream the
        session to a central recorder as well.
    Single producer: call ``record`` from one thread (the haptic loop).
    """

    def __init__(
        self,
        directory: str | Path,
        header: dict[str, Any],
        flush_interval: float = 0.1,
        capacity: int = 1 << 16,
        mirror: Callable[[str, pa.RecordBatch], object] | None = None,
    ) -> None:
        self.directory = Path(directory)
        self.directory.mkdir(parents=True, exist_ok=True)
        if (self.directory / SAMPLES_FILE).exists() or (self.directory / SAMPLES_JOURNAL).exists():
            raise RecorderError(f"session directory {self.directory} already holds a recording")
        self.flush_interval = flush_interval
        self.mirror = mirror
        # Ring and counters live in one shared mapping, so a producer in a forked process (the
        # real-time haptic process) records straight into this writer; backed by a tmpfs file
        # where possible, so a crash of this process leaves every recorded row for recover()
        width = len(SAMPLE_COLUMNS)
        self._mapping, self._ring_file = ring_mapping(8 * (capacity * width + COUNTER_CELLS))
        shared = np.frombuffer(self._mapping, dtype=np.float64)
        self._ring = shared[: capacity * width].reshape(capacity, width)
        self._counters = shared[capacity * width :]  # see HEAD, TAIL, DROPPED, FIRST_DROPPED, LAST_DROPPED
        self._capacity = capacity
        self.header = {
            **header,
            "schema_version": SCHEMA_VERSION,
            "status": "recording",
            "started_unix": clock.time(),
            "flush_interval_s": flush_interval,
            "journal_checksum": CHECKSUM_NAME,
            "ring": {
                "file": None if self._ring_file is None else str(self._ring_file),
                "capacity": capacity,
                "width": width,
            },
        }
        write_json_atomically(self.directory / HEADER_FILE, self.header)
        # record() is the compiled producer's own method (recorder/_ring.c), bound per writer: no
        # Python frame on the haptic path, whose calls come right after the loop's wait with cold
        # caches (paced p99 3-5 us here, the same push in Python 7-13 us)
        end = capacity * width
        self._producer = RingProducer(
            shared, self._ring, width, capacity,
            end + HEAD, end + TAIL, end + DROPPED, end + FIRST_DROPPED, end + LAST_DROPPED,
        )  # fmt: skip
        self.record = self._producer.record  # type: ignore[method-assign]
        self._events: list[tuple] = []
        self._events_lock = threading.Lock()
        self._flush_lock = threading.Lock()  # one flush at a time: the writer thread's, a caller's, close's
        self._block_lock = threading.Lock()  # record_block callers share the ring's head
        self._closed = False
        self._sample_sink = open(self.directory / SAMPLES_JOURNAL, "wb")
        self._sample_stream = ipc.new_stream(self._sample_sink, SAMPLE_SCHEMA)
        self._event_sink = open(self.directory / EVENTS_JOURNAL, "wb")
        self._event_stream = ipc.new_stream(self._event_sink, EVENT_SCHEMA)
        for sink in (self._sample_sink, self._event_sink):  # the schemas are durable from the start
            sink.flush()
            os.fsync(sink.fileno())
        self.durable_samples = 0
        self.flush_seconds: list[float] = []
        _warm_flush_path()
        self.scene = None  # a recorder.scene.SceneLog, written at close when set
        self._stop = threading.Event()
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name="vascsim-recorder", daemon=True)
        self._thread.start()

    # -- producer side (the haptic loop) ------------------------------------------------------
    def record(self, row: NDArray[np.float64]) -> bool:
        """Queue one sample row (columns as ``recorder.schema.SAMPLE_COLUMNS``); False if dropped.

        A 1-D contiguous float64 row (a numpy row or a memoryview of one; a memoryview is the
        cheapest) is copied as it is; anything else numpy can convert to a row goes through
        numpy's assignment, which also refuses a row of the wrong length (ValueError). Each
        writer replaces this method with its compiled producer's ``record`` (same contract).
        """
        return self._producer.record(row)

    def record_block(self, rows: NDArray[np.float64]) -> int:
        """Queue many rows at once (imports, replays); returns how many fitted. Safe from any thread
        against other ``record_block`` calls and flushes; ``record`` (the haptic loop's, lock-free)
        must not run at the same time from another thread."""
        with self._block_lock:
            self._check_open("record to")
            return self._push_block(rows)

    def _check_open(self, what: str) -> None:
        if self._closed:
            raise RecorderError(f"cannot {what} {self.directory}: the session writer is closed")

    def _push_block(self, rows: NDArray[np.float64]) -> int:
        counters = self._counters
        head = int(counters[HEAD])
        count = min(self._capacity - (head - int(counters[TAIL])), len(rows))
        start = head % self._capacity
        first = min(count, self._capacity - start)  # up to the end of the ring, then from its start
        self._ring[start : start + first] = rows[:first]
        self._ring[: count - first] = rows[first:count]
        counters[HEAD] = head + count
        return count

    def prefault(self) -> None:
        """Touch every page of the ring from the calling (producer) process, so recording never
        takes a first-touch page fault (after fork, shared pages are mapped lazily)."""
        self._ring.reshape(-1)[::512].sum()

    @property
    def dropped(self) -> int:
        """Samples dropped since the last flush (the ring was full)."""
        return int(self._counters[DROPPED])

    def event(
        self,
        time: float,
        kind: str,
        triangle: int = -1,
        barycentric: tuple[float, float, float] = (math.nan, math.nan, math.nan),
        entry_angle_deg: float = math.nan,
        tip_speed: float = math.nan,
        layer: str = "",
        detail: str = "",
    ) -> None:
        """Queue a discrete event (thread-safe; events are rare)."""
        with self._events_lock:
            self._events.append(
                (
                    float(time),
                    kind,
                    int(triangle),
                    *map(float, barycentric),
                    float(entry_angle_deg),
                    float(tip_speed),
                    layer,
                    detail,
                )
            )

    # -- writer thread ---------------------------------------------------------------------
    def _run(self) -> None:
        try:
            while not self._stop.wait(self.flush_interval):
                with self._flush_lock:
                    if self._stop.is_set():
                        break
                    self._flush()
        except BaseException as error:  # reported by close(); recording stops being durable
            self._error = error

    def flush(self) -> None:
        """Make everything queued so far durable (journal append + fsync); safe from any thread
        (flushes run one at a time). Raises :class:`RecorderError` once the writer is closed."""
        with self._flush_lock:
            self._check_open("flush")
            self._flush()

    def _flush(self) -> None:
        started = clock.perf_counter()
        head, tail = int(self._counters[HEAD]), int(self._counters[TAIL])
        written: list[tuple[str, pa.RecordBatch]] = []
        if head > tail:
            start, stop = tail % self._capacity, head % self._capacity
            if start < stop:  # one contiguous slice: no gather copy
                batch = samples_batch(self._ring[start:stop])
            else:
                batch = samples_batch(self._ring[np.arange(tail, head) % self._capacity])
            self._sample_stream.write_batch(batch, custom_metadata=sealed(batch))
            written.append(("samples", batch))
        self._note_drops()
        with self._events_lock:
            events, self._events = self._events, []
        if events:
            batch = events_batch(events)
            self._event_stream.write_batch(batch, custom_metadata=sealed(batch))
            written.append(("events", batch))
        for sink in (self._sample_sink, self._event_sink):
            sink.flush()
            os.fsync(sink.fileno())
        self._counters[TAIL] = head
        self.durable_samples = head
        if self.mirror is not None:
            for stream, batch in written:
                self.mirror(stream, batch)
        self.flush_seconds.append(clock.perf_counter() - started)

    def _note_drops(self) -> None:
        dropped = int(self._counters[DROPPED])
        if dropped:
            first, last = float(self._counters[FIRST_DROPPED]), float(self._counters[LAST_DROPPED])
            self.event(
                first,
                "queue_overflow",
                detail=f"{dropped} samples dropped between {first:.3f} s "
                f"and {last:.3f} s: the recorder could not keep up",
            )
            self.header["dropped_samples"] = self.header.get("dropped_samples", 0) + dropped
            self._counters[DROPPED] = 0

    # -- closing -------------------------------------------------------------------------------------
    def close(self, status: str = "complete") -> dict[str, Any]:
        """Final flush, Parquet conversion with verification and checksums; returns the header."""
        with self._flush_lock:
            self._check_open("close")
            self._stop.set()
        self._thread.join()
        if self._error is not None:
            raise RecorderError(f"recording to {self.directory} failed: {self._error}") from self._error
        with self._block_lock, self._flush_lock:
            self._check_open("close")
            self._flush()
            self._closed = True
        for stream, sink in (
            (self._sample_stream, self._sample_sink),
            (self._event_stream, self._event_sink),
        ):
            stream.close()
            sink.close()
        if self.scene is not None and len(self.scene):
            self.header["scene"] = write_scene(self.directory, self.scene.table())
        write_json_atomically(self.directory / HEADER_FILE, self.header)
        finished = finalize(self.directory, status)
        release_ring(self.header)
        return finished


def _warm_flush_path() -> None:
    """Run a flush's code once on a throwaway batch (imports, Arrow's kernels, the checksum), so a
    new process's first real flush is as quick as the rest instead of taking a quarter second."""
    sink = pa.BufferOutputStream()
    for schema, batch in (
        (SAMPLE_SCHEMA, samples_batch(np.zeros((2, len(SAMPLE_COLUMNS))))),
        (EVENT_SCHEMA, events_batch([(0.0, "contact_start", -1, 0.0, 0.0, 0.0, 0.0, 0.0, "", "")])),
    ):
        with ipc.new_stream(sink, schema) as stream:
            stream.write_batch(batch, custom_metadata=sealed(batch))


__all__ = [  # what other modules and tests import from here (docs/architecture.md: the module map)
    "EVENTS_JOURNAL",
    "SAMPLES_FILE",
    "SAMPLES_JOURNAL",
    "TRANSPOSE_BLOCK_ROWS",
    "SessionWriter",
    "columns_of",
    "events_batch",
    "finalize",
    "read_journal",
    "recover",
    "release_ring",
    "salvage_ring",
    "same_values",
    "samples_batch",
    "sha256_of",
]
