"""Shared-memory channels between the haptic process and the rest of the simulator.

An anonymous shared mapping created before ``fork`` is visible to both
processes. Each channel has one writer:

- :class:`SharedHolder` (haptic -> FEM): the latest holder pose, seqlock-protected;
- :class:`SharedForceHistory` (FEM -> haptic): a ring of (time, force), published
  entry first, counter second;
- :class:`SharedHapticLog` (haptic -> main): every tick's time, position, grip, force;
- :class:`SharedEvents` and :class:`ControlBlock` (the loops' telemetry: :mod:`sim.runtime.telemetry`).

They offer the same methods as the in-process versions, so the haptic layer's
step function runs unchanged on either side.
"""

from __future__ import annotations

import math
import mmap
import os
import time

import numpy as np
from numpy.typing import NDArray

from sim.needle import Pose
from sim.runtime.logs import HapticColumns, interpolate_force
from sim.runtime.snapshots import (
    FEM_LAYOUT,
    HAPTIC_LOG_LAYOUT,
    HOLDER_LAYOUT,
    MAX_SHARED_NEEDLE_VERTICES,
    STATE_CODES,
    FemSnapshot,
    GraphicsSnapshot,
    HolderSnapshot,
)


class Arena:
    """Carves float64 arrays out of one anonymous shared mapping."""

    def __init__(self, doubles: int) -> None:
        self._map = mmap.mmap(-1, 8 * doubles)
        self._all = np.frombuffer(self._map, dtype=np.float64)
        self._used = 0

    def take(self, *shape: int) -> NDArray[np.float64]:
        size = int(np.prod(shape))
        if self._used + size > len(self._all):
            raise MemoryError("shared arena too small")
        out = self._all[self._used : self._used + size].reshape(shape)
        out[...] = 0.0
        self._used += size
        return out


_STATE_NAMES = {code: name for name, code in STATE_CODES.items()}


def consistent_copy(slot: NDArray[np.float64]) -> NDArray[np.float64] | None:
    """Seqlock read: a copy taken while no write was in progress (None before the first write)."""
    for _ in range(1000):
        before = slot[0]
        copy = slot.copy()
        if before == slot[0] and before % 2 == 0:
            break
    return None if copy[0] == 0 else copy


class SharedHolder:
    """Latest holder snapshot, laid out as :data:`HOLDER_LAYOUT`."""

    @staticmethod
    def doubles() -> int:
        """Its size in the arena: a seqlock counter, time, position, rotation, velocity, grip."""
        return HOLDER_LAYOUT.size

    def __init__(self, arena: Arena) -> None:
        self._slot = arena.take(self.doubles())

    @property
    def cells(self) -> NDArray[np.float64]:
        """The slot itself (the compiled force path writes it: sim/runtime/_haptic.c)."""
        return self._slot

    def put(self, snapshot) -> None:
        slot, at = self._slot, HOLDER_LAYOUT.at
        slot[0] += 1  # odd: writing
        slot[at.time] = snapshot.time
        slot[at.position] = snapshot.pose.position
        slot[at.rotation] = snapshot.pose.rotation.ravel()
        slot[at.velocity] = snapshot.velocity
        slot[at.grip] = float(snapshot.grip)
        slot[0] += 1  # even: consistent

    def get(self):

        copy = consistent_copy(self._slot)
        if copy is None:
            return None
        at = HOLDER_LAYOUT.at
        pose = Pose.unchecked(copy[at.position], copy[at.rotation].reshape(3, 3))
        return HolderSnapshot(float(copy[at.time]), pose, copy[at.velocity], bool(copy[at.grip]))


class SharedForceHistory:
    """The FEM layer's (time, force) outputs in a shared ring, interpolated by the haptic process.

    ``at`` gives what :class:`sim.runtime.simulation.ForceHistory` gives for the same pushes over
    the last ``capacity - 1`` outputs, bit for bit: it bisects the ring's time column (a few scalar
    reads per haptic tick) and hands the two outputs around the time to ``interpolate_force``. On
    these VMs a step's compute time is sometimes stretched 5-20x by the host; what the step costs
    is what that multiplies.
    """

    @staticmethod
    def doubles(capacity: int = 512) -> int:
        """Its size in the arena: ``capacity`` rows of (time, force) and a counter."""
        return capacity * 4 + 1

    def __init__(self, arena: Arena, capacity: int = 512) -> None:
        self._ring = arena.take(capacity, 4)
        self._times = self._ring[:, 0]
        self._counter = arena.take(1)
        self._capacity = capacity

    @property
    def cells(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(the ring, its counter) for the compiled force path (sim/runtime/_haptic.c), a reader."""
        return self._ring, self._counter

    def push(self, time: float, force: NDArray[np.float64]) -> None:
        count = int(self._counter[0])
        row = self._ring[count % self._capacity]
        row[1:] = force
        row[0] = time
        self._counter[0] = count + 1  # publish after the entry is complete

    @property
    def latest_time(self) -> float | None:
        count = int(self._counter[0])
        return None if count == 0 else float(self._ring[(count - 1) % self._capacity, 0])

    def at(self, time: float) -> NDArray[np.float64]:
        """Force at ``time``: linear between the two outputs around it, held at the ends."""
        count = int(self._counter[0])  # entries before it are complete
        if count == 0:
            return np.zeros(3)
        ring, times, capacity = self._ring, self._times, self._capacity
        # the writer may be filling the slot after the newest: the oldest readable is one younger
        low, high = max(0, count - (capacity - 1)), count - 1
        if time >= times[high % capacity]:
            return ring[high % capacity, 1:].copy()
        if time < times[low % capacity]:
            return ring[low % capacity, 1:].copy()
        while high - low > 1:  # times[low] <= time < times[high]; pushes come in time order
            middle = (low + high) // 2
            if times[middle % capacity] <= time:
                low = middle
            else:
                high = middle
        t0, *a = ring[low % capacity].tolist()
        t1, *b = ring[high % capacity].tolist()
        return interpolate_force([t0, t1], [tuple(a), tuple(b)], time)  # the in-process arithmetic


class SharedHapticLog(HapticColumns):
    """The haptic log in shared memory: a row per tick (:data:`sim.runtime.snapshots.HAPTIC_LOG_LAYOUT`)."""

    @staticmethod
    def doubles(capacity: int) -> int:
        """Its size in the arena: ``capacity`` rows and a count."""
        return capacity * HAPTIC_LOG_LAYOUT.size + 1

    def __init__(self, arena: Arena, capacity: int) -> None:
        self._data = arena.take(capacity, HAPTIC_LOG_LAYOUT.size)
        self._count = arena.take(1)

    @property
    def cells(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(the rows, their count) for the compiled force path (sim/runtime/_haptic.c), the writer."""
        return self._data, self._count

    @property
    def count(self) -> int:
        return int(self._count[0])

    def append(self, time: float, position: NDArray, grip: bool, force: NDArray) -> None:
        index = self.count
        if index >= len(self._data):
            return  # full: the run outlived its planned duration; later ticks are not logged
        row, at = self._data[index], HAPTIC_LOG_LAYOUT.at
        row[at.time], row[at.position], row[at.grip], row[at.force] = time, position, float(grip), force
        self._count[0] = index + 1


EVENT_CODES = (
    "watchdog",
    "watchdog_recovered",
    "force_clamped",
    "nonfinite_force",
    "device_lost",
    "layer_failed",
    "tracking_lost",
    "tracking_regained",
)


class SharedEvents:
    """Runtime events raised in the haptic process: (time, code, detail) rows, the detail as at most
    :attr:`DETAIL_BYTES` of UTF-8 (cut at a character), so what the recording says of a clamped force
    ("1200 mN clamped to the rated 880 mN") is what the haptic process said."""

    DETAIL_BYTES = 96
    _ROW = 3 + DETAIL_BYTES // 8  # time, code, detail length, then the detail's bytes

    @classmethod
    def doubles(cls, capacity: int = 4096) -> int:
        """Its size in the arena: ``capacity`` rows and a count."""
        return capacity * cls._ROW + 1

    def __init__(self, arena: Arena, capacity: int = 4096) -> None:
        self._data = arena.take(capacity, self._ROW)
        self._count = arena.take(1)

    def add(self, time: float, kind: str, detail: str = "") -> None:
        index = int(self._count[0])
        if index < len(self._data):
            text = detail.encode()[: self.DETAIL_BYTES].decode(errors="ignore").encode()
            row = self._data[index]
            row[:3] = (time, EVENT_CODES.index(kind), len(text))
            row[3:].view(np.uint8)[: len(text)] = np.frombuffer(text, dtype=np.uint8)
            self._count[0] = index + 1

    def read(self, start: int = 0) -> list[tuple[float, str, str]]:
        end = int(self._count[0])
        return [
            (
                float(row[0]),
                EVENT_CODES[int(row[1])],
                row[3:].view(np.uint8)[: int(row[2])].tobytes().decode(),
            )
            for row in self._data[start:end]
        ]


def _text(row: NDArray[np.float64]) -> str:
    """The detail stored in an event row (its length, then its bytes)."""
    return row[3:].view(np.uint8)[: int(row[2])].tobytes().decode()


class ControlBlock:
    """[stop requested, haptic state, start time, haptic ready, display ready, display failed at]:
    states 0 running, 1 finished, 2 device lost, 3 failed. The start time (perf_counter seconds, shared
    by all processes) is 0 until the parent sets it, which it does only once the haptic process is
    ready. The stop word holds why the stop was asked for (an index into :data:`STOP_REASONS`, 0: not
    asked). The display's failure time is nan until the display process fails."""

    RUNNING, FINISHED, DEVICE_LOST, FAILED = 0.0, 1.0, 2.0, 3.0
    STOP_REASONS = ("", "stopped", "stopped_by_trainee", "interrupted", "task_done")
    """Why a stop was asked for: the run's end (``stopped``), the trainee (Escape, the device's
    button), Ctrl-C in the terminal (``interrupted``), every stitch of the task placed (``task_done``)."""

    @staticmethod
    def doubles() -> int:
        """Its size in the arena: six control words."""
        return 6

    def __init__(self, arena: Arena) -> None:
        self._data = arena.take(self.doubles())
        self._data[5] = math.nan

    @property
    def stop_requested(self) -> bool:
        return self._data[0] != 0.0

    def request_stop(self, reason: str = "stopped") -> None:
        """Ask every layer to stop; the first reason asked for is kept."""
        if self._data[0] == 0.0:
            self._data[0] = float(self.STOP_REASONS.index(reason))

    @property
    def stop_reason(self) -> str:
        """Why the stop was asked for ("" when it was not)."""
        return self.STOP_REASONS[int(self._data[0])]

    @property
    def haptic_state(self) -> float:
        return float(self._data[1])

    @haptic_state.setter
    def haptic_state(self, value: float) -> None:
        self._data[1] = value

    @property
    def start(self) -> float:
        return float(self._data[2])

    @start.setter
    def start(self, value: float) -> None:
        self._data[2] = value

    @property
    def haptic_ready(self) -> bool:
        return self._data[3] != 0.0

    def mark_haptic_ready(self) -> None:
        self._data[3] = 1.0

    @property
    def display_ready(self) -> bool:
        return self._data[4] != 0.0

    def mark_display_ready(self) -> None:
        self._data[4] = 1.0

    @property
    def display_failed_at(self) -> float:
        """Session time (s) at which the display process failed (0 before the session's start; nan
        while it has not)."""
        return float(self._data[5])

    def mark_display_failed(self, clock_now: float) -> None:
        """In the display process, as it fails at ``clock_now`` (the shared perf_counter clock): the
        session time then (0 before the start)."""
        start = float(self._data[2])
        self._data[5] = max(clock_now - start, 0.0) if start else 0.0

    def wait_for_start(self, poll: float = 0.0005) -> float:
        """The shared start time, once set (0.0 if a stop was requested first)."""
        while self._data[2] == 0.0 and not self.stop_requested:
            time.sleep(poll)
        return float(self._data[2])


class SharedGraphics:
    """The latest graphics snapshot for the display process: the needle, the FEM step's nodal loads on
    the tissue, the forceps' jaws and the holder sample's time (seqlock).

    Layout: [seq, time, n_vertices, vertices (64 x 3), n_loaded, nodes (256), forces (256 x 3),
    jaw point (3), jaws closed (nan: no forceps), soft share, holder time].
    """

    MAX_VERTICES = 64
    MAX_CONTACT = 256  # a needle through a wall (two force kernels of up to ~90 nodes) and a grasp (~50)

    @classmethod
    def doubles(cls) -> int:
        """Its size in the arena: a header, the needle's vertices, the loaded nodes and their forces,
        the jaws, the soft share and the holder sample's time."""
        return 3 + 3 * cls.MAX_VERTICES + 1 + cls.MAX_CONTACT * 4 + 4 + 2

    def __init__(self, arena: Arena) -> None:
        self._slot = arena.take(self.doubles())

    def put(self, snapshot) -> None:
        slot = self._slot
        vertices = snapshot.needle_vertices[: self.MAX_VERTICES]
        loads = snapshot.loads
        slot[0] += 1
        slot[1] = snapshot.time
        slot[2] = len(vertices)
        base = 3
        slot[base : base + 3 * len(vertices)] = vertices.ravel()
        base += 3 * self.MAX_VERTICES
        count = 0 if loads is None else min(len(loads[0]), self.MAX_CONTACT)
        slot[base] = count
        if count:
            slot[base + 1 : base + 1 + count] = loads[0][:count]
            start = base + 1 + self.MAX_CONTACT
            slot[start : start + 3 * count] = loads[1][:count].ravel()
        slot[-6:-3], slot[-3] = _jaw_cells(snapshot.jaws)
        slot[-2] = math.nan if loads is None else loads[2]
        slot[-1] = snapshot.holder_time
        slot[0] += 1

    def get(self):
        copy = consistent_copy(self._slot)
        if copy is None:
            return None
        n = int(copy[2])
        vertices = copy[3 : 3 + 3 * n].reshape(n, 3)
        base = 3 + 3 * self.MAX_VERTICES
        count = int(copy[base])
        loads = None
        if count:
            nodes = copy[base + 1 : base + 1 + count].astype(np.int64)
            start = base + 1 + self.MAX_CONTACT
            loads = (nodes, copy[start : start + 3 * count].reshape(count, 3), float(copy[-2]))
        jaws = _jaws_of(copy[-6:-3], copy[-3])
        return GraphicsSnapshot(float(copy[1]), vertices, "", None, None, float(copy[-1]), loads, jaws)


class SharedFem:
    """The FEM layer's snapshot: whole in the process that writes it, and the fields the haptic
    process records (tip, speed, direction, contact triangle, barycentrics, state) in shared memory.

    Laid out as :data:`FEM_LAYOUT`.
    """

    @staticmethod
    def doubles() -> int:
        """Its size in the arena: a seqlock counter, the step's state, force, stress, stretch and tip
        velocity."""
        return FEM_LAYOUT.size

    def __init__(self, arena: Arena, for_display: bool = False) -> None:
        self._slot = arena.take(self.doubles())
        self._owner = os.getpid()
        self._local = None
        self.for_display = for_display
        """Also share the whole needle, the jaws and the sample time (1.5 us a FEM step): a display
        process draws the instruments from them (without: the tip, no jaws, no sample time)."""
        self._slot[FEM_LAYOUT.at.holder_time] = self._slot[FEM_LAYOUT.at.jaws_closed] = math.nan

    def put(self, snapshot) -> None:
        self._local = snapshot
        slot, at = self._slot, FEM_LAYOUT.at
        slot[0] += 1
        slot[at.time] = snapshot.time
        slot[at.tip] = snapshot.needle_vertices[0]
        slot[at.tip_speed] = snapshot.tip_speed
        slot[at.tangent] = snapshot.tip_tangent if snapshot.tip_tangent is not None else 0.0
        slot[at.triangle] = snapshot.contact_triangle
        slot[at.barycentric] = snapshot.barycentric
        slot[at.state] = STATE_CODES.get(snapshot.state, 0)
        slot[at.needle_force] = snapshot.needle_force
        slot[at.local_stress] = snapshot.local_stress
        slot[at.stretch] = snapshot.stretch
        slot[at.tip_velocity] = _nan_if_none(snapshot.tip_velocity)
        slot[at.grasp_force] = _nan_if_none(snapshot.grasp_force)
        slot[at.grasp_displacement] = _nan_if_none(snapshot.grasp_displacement)
        slot[at.wrist_at_stop] = float(snapshot.wrist_at_stop)
        if self.for_display:
            self._put_instruments(slot, at, snapshot)
        slot[0] += 1

    @staticmethod
    def _put_instruments(slot, at, snapshot) -> None:
        vertices = snapshot.needle_vertices
        whole = len(vertices) <= MAX_SHARED_NEEDLE_VERTICES
        slot[at.needle_count] = len(vertices) if whole else 0
        if whole:
            slot[at.needle.start : at.needle.start + vertices.size] = vertices.ravel()
        slot[at.holder_time] = snapshot.holder_time
        slot[at.jaw_point], slot[at.jaws_closed] = _jaw_cells(snapshot.jaws)

    def get(self):
        if os.getpid() == self._owner:
            return self._local
        copy = consistent_copy(self._slot)
        if copy is None:
            return None
        at = FEM_LAYOUT.at
        state = _STATE_NAMES.get(int(copy[at.state]), "free")
        count = int(copy[at.needle_count])
        needle = copy[at.needle][: 3 * count].reshape(count, 3) if count else copy[at.tip].reshape(1, 3)
        return FemSnapshot(
            time=float(copy[at.time]),
            needle_force=copy[at.needle_force],
            needle_vertices=needle,
            state=state,
            contact_nodes=np.zeros(0, dtype=np.int64),
            reaction_forces=np.zeros((0, 3)),
            tip_speed=float(copy[at.tip_speed]),
            tip_tangent=copy[at.tangent],
            contact_triangle=int(copy[at.triangle]),
            barycentric=tuple(float(w) for w in copy[at.barycentric]),
            local_stress=float(copy[at.local_stress]),
            stretch=float(copy[at.stretch]),
            tip_velocity=copy[at.tip_velocity],
            grasp_force=_none_if_nan(copy[at.grasp_force]),
            grasp_displacement=_none_if_nan(copy[at.grasp_displacement]),
            wrist_at_stop=bool(copy[at.wrist_at_stop]),
            holder_time=float(copy[at.holder_time]),
            jaws=_jaws_of(copy[at.jaw_point], copy[at.jaws_closed]),
        )


def _nan_if_none(value):
    return math.nan if value is None else value


def _none_if_nan(cells: NDArray[np.float64]) -> NDArray[np.float64] | None:
    return None if math.isnan(cells[0]) else cells


def _jaw_cells(jaws: tuple[NDArray[np.float64], bool] | None) -> tuple:
    """The forceps' jaws as slot cells: (jaw point, closed), nan for a one-handed scene."""
    return (math.nan, math.nan) if jaws is None else (jaws[0], float(jaws[1]))


def _jaws_of(point: NDArray[np.float64], closed: float) -> tuple[NDArray[np.float64], bool] | None:
    return None if math.isnan(closed) else (point, bool(closed))
