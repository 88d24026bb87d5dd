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
import mmap
import os
import re
import threading
import time as clock
import uuid
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.ipc as ipc
import pyarrow.parquet as pq
from numpy.typing import NDArray

from recorder._ring import RingProducer
from recorder.integrity import CHECKSUM_NAME, scan_journal, sealed
from recorder.layout import (
    EVENTS_FILE,
    EVENTS_JOURNAL,
    HEADER_FILE,
    SAMPLES_FILE,
    SAMPLES_JOURNAL,
    read_header,
    sha256_of,
    write_json_atomically,
)
from recorder.scene import write_scene
from recorder.schema import (
    EVENT_SCHEMA,
    INTEGER_COLUMNS,
    SAMPLE_COLUMNS,
    SAMPLE_SCHEMA,
    SCHEMA_VERSION,
    RecorderError,
)

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


_INTEGER_DTYPES = {name: np.dtype(str(kind)) for name, kind in INTEGER_COLUMNS.items()}
"""NumPy dtypes of the integer columns (``DataType.to_pandas_dtype`` would import pandas: 0.3 s)."""


def samples_batch(rows: NDArray[np.float64]) -> pa.RecordBatch:
    """An Arrow batch of the sample schema from (n, columns) float rows."""
    columns = columns_of(rows)
    arrays = []
    for i, name in enumerate(SAMPLE_COLUMNS):
        kind = _INTEGER_DTYPES.get(name)
        column = columns[i]
        arrays.append(pa.array(column.astype(kind) if kind is not None else column))
    return pa.RecordBatch.from_arrays(arrays, schema=SAMPLE_SCHEMA)


def events_batch(events: list[tuple]) -> pa.RecordBatch:
    """An Arrow batch of the event schema from event tuples (see ``SessionWriter.event``)."""
    columns = list(zip(*events, strict=True)) if events else [[] for _ in EVENT_SCHEMA]
    return pa.RecordBatch.from_arrays(
        [pa.array(c, type=f.type) for c, f in zip(columns, EVENT_SCHEMA, strict=True)],
        schema=EVENT_SCHEMA,
    )


RING_DIRECTORY = Path("/dev/shm")
"""Where a writer's ring lives as a file (tmpfs: memory, as fast as an anonymous mapping, and still
there after the recording process dies). Without it, or without room, the ring is anonymous."""


def _ring_mapping(size: int) -> tuple[mmap.mmap, Path | None]:
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
        # Ring and counters live in one shared mapping, so a producer in a forked process (the
        # real-time haptic process) records straight into this writer; backed by a tmpfs file
        # where possible, so a crash of this process leaves every recorded row for recover()
        width = len(SAMPLE_COLUMNS)
        self._mapping, self._ring_file = _ring_mapping(8 * (capacity * width + COUNTER_CELLS))
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


def read_journal(path: Path, schema: pa.Schema, require_checksums: bool = False) -> tuple[pa.Table, bool]:
    """Every verified batch of an IPC journal up to the first that does not verify (torn, damaged,
    or failing its checksum); the flag says whether anything after them was cut off."""
    scan = scan_journal(path, schema, require_checksums)
    return pa.Table.from_batches(scan.batches, schema=schema), scan.cut() is not None


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


def finalize(
    directory: Path, status: str, extra: dict[str, Any] | None = None, salvaged: pa.RecordBatch | None = None
) -> dict[str, Any]:
    """Journals -> verified Parquet files with SHA-256 in the header; journals removed last.

    Each journal is read up to its first batch that fails to verify; what was cut is recorded in
    the header (``samples.cut`` / ``events.cut``). ``salvaged``: sample rows recovered from the
    recording's memory after the journal's last batch (see ``recover``)."""
    header = read_header(directory)
    required = header.get("journal_checksum") == CHECKSUM_NAME
    staged: list[tuple[Path, Path]] = []  # (verified temporary, its final name): replaced together
    try:
        for journal, target, schema, key in (
            (SAMPLES_JOURNAL, SAMPLES_FILE, SAMPLE_SCHEMA, "samples"),
            (EVENTS_JOURNAL, EVENTS_FILE, EVENT_SCHEMA, "events"),
        ):
            if not (directory / journal).is_file():
                raise RecorderError(f"{directory / journal} is missing; the session cannot be finished")
            scan = scan_journal(directory / journal, schema, required)
            batches = scan.batches + ([salvaged] if key == "samples" and salvaged is not None else [])
            table = pa.Table.from_batches(batches, schema=schema)
            temporary = directory / (target + ".tmp")
            staged.append((temporary, directory / target))
            pq.write_table(table, temporary, compression="zstd")
            if not same_values(pq.read_table(temporary), table):
                raise RecorderError(f"verification of {temporary} failed; the journal {journal} is kept")
            header[key] = _stream_entry(target, temporary, table, scan.cut())
        for temporary, final in staged:  # only once both verified: a failure leaves no Parquet behind
            os.replace(temporary, final)
    finally:
        for temporary, _ in staged:
            temporary.unlink(missing_ok=True)
    header.update(extra or {})
    header["status"] = status
    header["closed_unix"] = clock.time()
    write_json_atomically(directory / HEADER_FILE, header)
    for journal in (SAMPLES_JOURNAL, EVENTS_JOURNAL):
        (directory / journal).unlink(missing_ok=True)
    return header


def _stream_entry(name: str, written: Path, table: pa.Table, cut: dict[str, Any] | None) -> dict[str, Any]:
    """A finished stream's header entry: its file, rows, SHA-256, time range and what was cut."""
    entry: dict[str, Any] = {"file": name, "rows": table.num_rows, "sha256": sha256_of(written)}
    entry["torn_tail_cut"] = cut is not None
    if cut is not None:
        entry["cut"] = cut
    if name == SAMPLES_FILE and table.num_rows:
        times = table.column("time").to_numpy()
        entry["time_range_s"] = [float(times[0]), float(times[-1])]
    return entry


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


def recover(directory: str | Path) -> dict[str, Any]:
    """Turn the journals a crash left behind into a valid session marked ``recovered``.

    The journals are kept up to their first batch that fails to verify (torn or damaged: what
    was cut is recorded). If the recording process died but the machine did not, its ring
    (tmpfs) still holds every row it recorded: rows after the journal's last batch are checked
    and kept, and the header says so. The header records, measured: the last durable sample
    (``durable_until_s``), the last kept one (``recovered_until_s``), the time between them
    (``unflushed_s``) and what may be lost (``lost_at_most_s``: 0 when the ring accounted for
    every recorded row, null when the ring was gone and the extent is unknown).
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
    required = header.get("journal_checksum") == CHECKSUM_NAME
    durable, _ = read_journal(directory / SAMPLES_JOURNAL, SAMPLE_SCHEMA, required)
    salvaged, ring, problem = salvage_ring(header, durable)
    durable_until = float(durable.column("time")[-1].as_py()) if durable.num_rows else None
    kept_until = float(salvaged.column(0)[-1].as_py()) if salvaged is not None else durable_until
    interval = header.get("flush_interval_s")
    if ring is not None:
        missing = ring["dropped_unflushed"]
        note = (
            f"every sample recorded was kept ({durable.num_rows} from the journal, "
            f"{0 if salvaged is None else salvaged.num_rows} from the recording's memory)"
            + (f"; {missing} samples the recorder could not keep up with were dropped" if missing else "")
            + (f"; events after {durable_until:.3f} s may be missing" if durable_until is not None else "")
        )
    else:
        note = (
            f"{problem}: samples recorded after the last durable one were lost and how many is "
            f"unknown (the writer made its journal durable every {interval} s)"
        )
    lost = {
        "recovered": True,
        "durable_until_s": durable_until,
        "recovered_until_s": kept_until,
        "lost_after_s": kept_until,
        "unflushed_s": None if durable_until is None or kept_until is None else kept_until - durable_until,
        "salvaged_samples": 0 if salvaged is None else salvaged.num_rows,
        "lost_at_most_s": 0.0 if ring is not None else None,
        "loss_note": note,
    }
    if ring is not None and ring["dropped_unflushed"]:
        lost["dropped_samples"] = header.get("dropped_samples", 0) + ring["dropped_unflushed"]
    finished = finalize(directory, "recovered", lost, salvaged)
    release_ring(header)
    return finished
