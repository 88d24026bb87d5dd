"""Durable session recording that never blocks the haptic loop.

``record(row)`` copies one sample row into a preallocated ring (a compiled push,
``recorder._ring``: well under a microsecond with warm caches, no locks, no
allocation) and returns; a background thread turns
the rows written since its last pass into an Arrow record batch, appends it to
an append-only journal (Arrow IPC stream) and fsyncs it every
``flush_interval`` (100 ms by default), so a crash loses at most that interval.
If the ring fills up (the disk stalls), samples are dropped and counted, and a
``queue_overflow`` event records how many and over which time range: nothing is
lost silently. ``close()`` turns the journals into Parquet (zstd), verifies them,
records their SHA-256 in ``header.json``, and only then removes the journals.

Session directory: ``header.json``, ``samples.arrows`` / ``events.arrows``
(journals while recording), ``samples.parquet`` / ``events.parquet`` (after close).
"""

from __future__ import annotations

import hashlib
import json
import math
import mmap
import os
import threading
import time as clock
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.ipc as ipc
import pyarrow.parquet as pq
from numpy.typing import NDArray

from recorder._ring import RingProducer
from recorder.schema import (
    EVENT_SCHEMA,
    INTEGER_COLUMNS,
    SAMPLE_COLUMNS,
    SAMPLE_SCHEMA,
    SCHEMA_VERSION,
    RecorderError,
)

SAMPLES_JOURNAL, EVENTS_JOURNAL = "samples.arrows", "events.arrows"
SAMPLES_FILE, EVENTS_FILE, HEADER_FILE = "samples.parquet", "events.parquet", "header.json"


def sha256_of(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for chunk in iter(lambda: handle.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()


def write_json_atomically(path: Path, data: dict[str, Any]) -> None:
    temporary = path.with_suffix(path.suffix + ".tmp")
    with open(temporary, "w") as handle:
        json.dump(data, handle, indent=2, sort_keys=True, allow_nan=False)  # NaN is not JSON
        handle.flush()
        os.fsync(handle.fileno())
    os.replace(temporary, path)


def read_header(directory: Path) -> dict[str, Any]:
    """A session directory's ``header.json``; RecorderError if it is missing, damaged or not an object."""
    path = directory / HEADER_FILE
    try:
        header = json.loads(path.read_bytes().decode("utf-8"))
    except FileNotFoundError:
        raise RecorderError(f"{directory} is not a session directory (no {HEADER_FILE})") from None
    except (UnicodeDecodeError, json.JSONDecodeError) as error:
        raise RecorderError(f"{path} is not valid JSON (damaged?): {error}") from error
    if not isinstance(header, dict):
        raise RecorderError(f"{path} holds a JSON {type(header).__name__}, not a session header object")
    return header


TRANSPOSE_BLOCK_ROWS = 512
"""Rows transposed at a time: a block of rows (139 kB) stays in cache while it is scattered into
columns, 4x faster than one strided copy of the whole flush (which re-reads each row per column)."""


def columns_of(rows: NDArray[np.float64]) -> NDArray[np.float64]:
    """(n, columns) rows as a C-contiguous (columns, n) array, transposed block by block."""
    columns = np.empty((rows.shape[1], rows.shape[0]))
    for start in range(0, rows.shape[0], TRANSPOSE_BLOCK_ROWS):
        stop = start + TRANSPOSE_BLOCK_ROWS
        columns[:, start:stop] = rows[start:stop].T
    return columns


def samples_batch(rows: NDArray[np.float64]) -> pa.RecordBatch:
    """An Arrow batch of the sample schema from (n, columns) float rows."""
    columns = columns_of(rows)
    arrays = []
    for i, name in enumerate(SAMPLE_COLUMNS):
        kind = INTEGER_COLUMNS.get(name)
        column = columns[i]
        arrays.append(pa.array(column.astype(kind.to_pandas_dtype()) if kind else column))
    return pa.RecordBatch.from_arrays(arrays, schema=SAMPLE_SCHEMA)


HEAD, TAIL, DROPPED, FIRST_DROPPED, LAST_DROPPED = 0, 8, 16, 17, 18
"""Cells after the ring: rows written (producer), rows flushed (writer), and the drop count and
time range since the last flush. Head and tail sit 64 bytes apart, on cache lines of their own:
the producer's record() never misses on a line the writer has just written."""
COUNTER_CELLS = 24


class SessionWriter:
    """Records one session into ``directory`` (see the module docstring).

    header: session metadata (participant, session ids, task, mesh hash,
        materials, model parameters, device, software version, clock mode, ...).
    mirror: called from the writer thread with ("samples" | "events", batch) for every batch
        once it is durable here, e.g. ``recorder.station.StationUploader.submit`` to stream the
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
        self.header = {
            **header,
            "schema_version": SCHEMA_VERSION,
            "status": "recording",
            "started_unix": clock.time(),
            "flush_interval_s": flush_interval,
        }
        write_json_atomically(self.directory / HEADER_FILE, self.header)
        # Ring and counters live in an anonymous shared mapping, so a producer in a forked
        # process (the real-time haptic process) records straight into this writer.
        width = len(SAMPLE_COLUMNS)
        shared = np.frombuffer(mmap.mmap(-1, 8 * (capacity * width + COUNTER_CELLS)), dtype=np.float64)
        self._ring = shared[: capacity * width].reshape(capacity, width)
        self._counters = shared[capacity * width :]  # see HEAD, TAIL, DROPPED, FIRST_DROPPED, LAST_DROPPED
        self._capacity = capacity
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
            self._sample_stream.write_batch(batch)
            written.append(("samples", batch))
        self._note_drops()
        with self._events_lock:
            events, self._events = self._events, []
        if events:
            columns = list(zip(*events, strict=True))
            batch = pa.RecordBatch.from_arrays(
                [pa.array(c, type=f.type) for c, f in zip(columns, EVENT_SCHEMA, strict=True)],
                schema=EVENT_SCHEMA,
            )
            self._event_stream.write_batch(batch)
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
            from recorder.scene import write_scene

            self.header["scene"] = write_scene(self.directory, self.scene.table())
        write_json_atomically(self.directory / HEADER_FILE, self.header)
        return finalize(self.directory, status)


def read_journal(path: Path, schema: pa.Schema) -> tuple[pa.Table, bool]:
    """Every complete, valid batch of an IPC journal; the flag says whether a torn or damaged tail
    was cut off (reading stops at the first batch that does not validate)."""
    batches, torn = [], False
    try:
        with pa.OSFile(str(path), "rb") as source:
            reader = ipc.open_stream(source)
            if not reader.schema.equals(schema, check_metadata=False):
                kind = schema.metadata[b"vascsim.schema"].decode()
                raise RecorderError(f"{path} does not hold the {kind} schema (damaged journal header)")
            while True:
                try:
                    batch = reader.read_next_batch()
                except StopIteration:
                    break
                batch.validate(full=True)
                batches.append(batch)
    except (pa.ArrowException, OSError, EOFError):
        torn = True
    return pa.Table.from_batches(batches, schema=schema), torn


def same_values(a: pa.Table, b: pa.Table) -> bool:
    """Column-by-column equality, NaN equal to NaN (Table.equals treats NaN as different)."""
    if a.num_rows != b.num_rows or a.column_names != b.column_names:
        return False
    for name in a.column_names:
        x, y = a.column(name).to_numpy(zero_copy_only=False), b.column(name).to_numpy(zero_copy_only=False)
        if x.dtype.kind == "f":
            if not np.array_equal(x, y, equal_nan=True):
                return False
        elif x.tolist() != y.tolist():
            return False
    return True


def finalize(directory: Path, status: str, extra: dict[str, Any] | None = None) -> dict[str, Any]:
    """Journals -> verified Parquet files with SHA-256 in the header; journals removed last."""
    header = read_header(directory)
    for journal, target, schema, key in (
        (SAMPLES_JOURNAL, SAMPLES_FILE, SAMPLE_SCHEMA, "samples"),
        (EVENTS_JOURNAL, EVENTS_FILE, EVENT_SCHEMA, "events"),
    ):
        table, torn = read_journal(directory / journal, schema)
        temporary = directory / (target + ".tmp")
        pq.write_table(table, temporary, compression="zstd")
        check = pq.read_table(temporary)
        if not same_values(check, table):
            raise RecorderError(f"verification of {temporary} failed; the journal {journal} is kept")
        os.replace(temporary, directory / target)
        header[key] = {
            "file": target,
            "rows": table.num_rows,
            "sha256": sha256_of(directory / target),
            "torn_tail_cut": torn,
        }
        if key == "samples" and table.num_rows:
            times = table.column("time").to_numpy()
            header[key]["time_range_s"] = [float(times[0]), float(times[-1])]
    header.update(extra or {})
    header["status"] = status
    header["closed_unix"] = clock.time()
    write_json_atomically(directory / HEADER_FILE, header)
    for journal in (SAMPLES_JOURNAL, EVENTS_JOURNAL):
        (directory / journal).unlink(missing_ok=True)
    return header


def recover(directory: str | Path) -> dict[str, Any]:
    """Turn the journals a crash left behind into a valid session marked ``recovered``.

    Everything up to the last complete journal batch is kept; the header records the
    recovered time range and that at most one flush interval after it was lost.
    """
    directory = Path(directory)
    if not (directory / SAMPLES_JOURNAL).exists():
        raise RecorderError(f"{directory} has no journal to recover (nothing was being recorded there)")
    if not (directory / HEADER_FILE).exists():
        raise RecorderError(f"{directory} has a journal but no header.json; cannot tell which session it is")
    header = read_header(directory)
    if header.get("schema_version") != SCHEMA_VERSION:
        raise RecorderError(
            f"{directory / HEADER_FILE}: schema version {header.get('schema_version')!r} is not one this "
            f"vascsim writes ({SCHEMA_VERSION}); the journal is left as it is"
        )
    table, _ = read_journal(directory / SAMPLES_JOURNAL, SAMPLE_SCHEMA)
    last = float(table.column("time").to_numpy()[-1]) if table.num_rows else None
    lost = {
        "recovered": True,
        "recovered_until_s": last,
        "lost_after_s": last,
        "lost_at_most_s": header.get("flush_interval_s"),
    }
    return finalize(directory, "recovered", lost)
