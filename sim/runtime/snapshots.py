"""What the layers hand each other: snapshots of the holder, the FEM step and the graphics frame,
runtime events, and the holder's and FEM step's slots in shared memory laid out by name. Its own
module, so the shared-memory channels (sim.runtime.shared) and the simulation both import it at the
top, with no circle between them."""

from __future__ import annotations

import math
import types
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from sim.needle import Pose


# The snapshots are NamedTuples: as immutable as frozen dataclasses, and built in a third of the
# time (a frozen dataclass sets each field through object.__setattr__; one is made every tick).
class HolderSnapshot(NamedTuple):
    time: float
    pose: Pose
    velocity: NDArray[np.float64]
    grip: bool


class FemSnapshot(NamedTuple):
    time: float
    needle_force: NDArray[np.float64]
    needle_vertices: NDArray[np.float64]
    state: str
    contact_nodes: NDArray[np.int64]
    reaction_forces: NDArray[np.float64]
    contact: Sequence[NDArray] | None = None  # (driven nodes, intended (m)): a pair, or a KernelDrive
    tip_speed: float = 0.0
    tip_tangent: NDArray[np.float64] | None = None
    contact_triangle: int = -1
    barycentric: tuple[float, float, float] = (math.nan, math.nan, math.nan)
    soft_share: float = math.nan  # the biphase split of the drive (nan: the drive's own strain sets it)
    local_stress: float = math.nan  # Pa, largest von Mises stress within 1 mm of the contact
    stretch: float = math.nan  # the largest edge stretch around the contact in the field the display draws
    holder_time: float = math.nan  # s, the device sample the step's needle follows
    tip_velocity: NDArray[np.float64] | None = None  # m/s, the tip's between the last two FEM steps
    grasp_force: NDArray[np.float64] | None = None  # N, the subordinate hand's forceps on the tissue
    grasp_displacement: NDArray[np.float64] | None = None  # m, of the tissue the forceps hold
    grasp_loads: tuple[NDArray[np.int64], NDArray[np.float64]] | None = None  # grasped nodes, forces (k, 3) N
    jaws: tuple[NDArray[np.float64], bool] | None = None  # the forceps' jaw point (m) and whether closed
    wrist_at_stop: bool = False  # the task's approach holds the needle hand's wrist (sim.needle.reach)


STATE_CODES = {"free": 0, "contact": 1, "pierced": 2, "exited": 3}


class GraphicsSnapshot(NamedTuple):
    time: float
    needle_vertices: NDArray[np.float64]
    state: str
    hits: object
    contact: Sequence[NDArray] | None = None  # (driven nodes, intended (m)): a pair, or a KernelDrive
    holder_time: float = math.nan  # s, the device sample whose needle the frame shows (motion to photon)
    loads: tuple[NDArray[np.int64], NDArray[np.float64], float] | None = None
    """The FEM step's nodal loads on the tissue (the needle's and the forceps' grasp): node ids, forces
    (k, 3) N, and the biphase soft share (nan: one phase); the display shows their displacement field
    with one solve."""
    jaws: tuple[NDArray[np.float64], bool] | None = None  # the forceps' jaw point (m), closed; None: one hand


@dataclass(frozen=True)
class RuntimeEvent:
    """A runtime-level event: safety actions, device loss, a layer's failure, the stop."""

    kind: str
    time: float
    layer: str
    detail: str = ""


class Mailbox:
    """A slot holding the latest immutable snapshot; replacing the reference is atomic."""

    __slots__ = ("_value",)

    def __init__(self, value: object = None) -> None:
        self._value = value

    def put(self, value: object) -> None:
        self._value = value

    def get(self) -> object:
        return self._value


class SlotLayout:
    """Named places in a shared slot, from one declaration of (name, doubles) in order: a field of one
    double is an index, a wider one a slice. ``size`` is the slot's length; ``at`` has each place as
    an attribute (``layout.at.time``: what the 1 kHz readers use, one attribute lookup a field)."""

    def __init__(self, fields: tuple[tuple[str, int], ...]) -> None:
        self.fields = fields
        places: dict[str, int | slice] = {}
        start = 0
        for name, size in fields:
            places[name] = start if size == 1 else slice(start, start + size)
            start += size
        self.size = start
        self.at = types.SimpleNamespace(**places)

    def __getitem__(self, name: str) -> int | slice:
        return getattr(self.at, name)

    def spans(self, names: tuple[str, ...]) -> tuple[tuple[int, int], ...]:
        """(start, width) of each named field, in the order asked (what compiled code is given)."""
        places = [self[name] for name in names]
        return tuple((p, 1) if isinstance(p, int) else (p.start, p.stop - p.start) for p in places)


HOLDER_LAYOUT = SlotLayout(
    (("seq", 1), ("time", 1), ("position", 3), ("rotation", 9), ("velocity", 3), ("grip", 1))
)
"""The holder slot (a seqlock counter first). The compiled force path (sim/runtime/_haptic.c) is given
these places by name (:data:`sim.runtime.force_path.HOLDER_FIELDS`) and writes the slot there."""
HAPTIC_LOG_LAYOUT = SlotLayout((("time", 1), ("position", 3), ("grip", 1), ("force", 3)))
"""A haptic log row: each tick's time, holder position, grip and the force sent (the Python logs and the
compiled force path, which is given these places by name, write it)."""
MAX_SHARED_NEEDLE_VERTICES = 64
"""A needle of up to this many vertices (the default has 17) is shared whole; a longer one by its tip."""
FEM_LAYOUT = SlotLayout(
    (
        ("seq", 1),
        ("time", 1),
        ("tip", 3),
        ("tip_speed", 1),
        ("tangent", 3),
        ("triangle", 1),
        ("barycentric", 3),
        ("state", 1),
        ("needle_force", 3),
        ("local_stress", 1),
        ("stretch", 1),
        ("tip_velocity", 3),
        ("grasp_force", 3),
        ("grasp_displacement", 3),
        ("wrist_at_stop", 1),
        ("needle_count", 1),
        ("needle", 3 * MAX_SHARED_NEEDLE_VERTICES),
        ("holder_time", 1),
        ("jaw_point", 3),
        ("jaws_closed", 1),
    )
)
"""The FEM snapshot's fields the haptic process records, in shared memory (a seqlock counter first),
and what the display draws the instruments from (the whole needle, the holder sample's time, the
forceps' jaws: a person's view shows the newest FEM step's instruments, docs/station.md)."""
