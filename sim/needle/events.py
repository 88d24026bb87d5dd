"""What the needle-tissue interaction reports: its states' transitions as events, each FEM step's
forces, the piercing rules, and the entry angle they are judged by.

Value types only (no state): the runtime, the recorder's event schema and the metrics read these
without the interaction's machinery (:mod:`sim.needle.interaction`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from sim.errors import VascsimError

EVENT_KINDS = (
    "contact_start",
    "contact_end",
    "pierce",
    "exit",
    "pull_through",
    "release",
    "regrab",
    "implausible_hit",
    "overstress",
    "edge_overstress",
    "tear",
    "wrist_stop",
)

NEEDLE_STATES = {
    "free": "the needle clear of the tissue",
    "contact": "the needle pressing on the wall",
    "pierced": "the needle in the wall, its tip not yet out",
    "exited": "the needle through the wall, its tip out",
}
"""The needle's states in the words an event's detail uses (a supervisor reads them in the event list)."""


class InteractionError(VascsimError, ValueError):
    """Bad input to the needle-tissue interaction."""


@dataclass(frozen=True)
class PiercingRules:
    """Thresholds of the piercing decision and grasping.

    max_entry_angle_deg: largest angle between the needle tip's direction and the
        inward surface normal at which the needle can pierce (grazing entries slide).
    puncture_stress: tip stress (Pa) at which a well-aligned needle pierces: the
        normal reaction over the wire's cross-section. The default 100 kPa suits the
        paper's soft tissue (E1 = 20 kPa): a 0.25 mm needle pierces a 1.5 mm wall
        patch at about 0.65 mm indentation at rest and the 10 mm cube at 0.25 mm.
    regrab_distance: a closing grip re-grabs the needle if the holder's jaw point is
        within this distance (m) of the needle.
    """

    max_entry_angle_deg: float = 45.0
    puncture_stress: float = 1e5
    regrab_distance: float = 0.002

    def __post_init__(self) -> None:
        if not 0 < self.max_entry_angle_deg <= 90:
            raise InteractionError(f"max_entry_angle_deg must be in (0, 90]; got {self.max_entry_angle_deg}")
        if not self.puncture_stress > 0:
            raise InteractionError(f"puncture_stress must be positive (Pa); got {self.puncture_stress}")
        if not self.regrab_distance > 0:
            raise InteractionError(f"regrab_distance must be positive (m); got {self.regrab_distance}")


@dataclass(frozen=True)
class NeedleEvent:
    """A transition of the needle-tissue state, with where and how it happened.

    time (s); triangle: exterior triangle id (-1 if none); barycentric (3,);
    entry_angle_deg: angle to the inward normal (nan if not applicable);
    tip_speed (m/s); detail: a short readable note.
    """

    kind: str
    time: float
    triangle: int = -1
    barycentric: tuple[float, float, float] = (math.nan, math.nan, math.nan)
    entry_angle_deg: float = math.nan
    tip_speed: float = math.nan
    detail: str = ""


@dataclass(frozen=True)
class FemStep:
    """Result of one FEM-rate step: the force on the needle (N) and the nodal reactions."""

    needle_force: NDArray[np.float64]
    contact_nodes: NDArray[np.int64]
    reaction_forces: NDArray[np.float64]
    events: list[NeedleEvent] = field(default_factory=list)

    @classmethod
    def untouched(cls, events: list[NeedleEvent] | None = None) -> FemStep:
        """No contact: zero force, no nodes (shared read-only arrays; most FEM steps of a free needle)."""
        return cls(_NO_FORCE, _NO_NODES, _NO_REACTIONS, [] if events is None else events)


def _read_only(array: NDArray) -> NDArray:
    array.flags.writeable = False
    return array


_NO_FORCE = _read_only(np.zeros(3))
_NO_NODES = _read_only(np.zeros(0, dtype=np.int64))
_NO_REACTIONS = _read_only(np.zeros((0, 3)))


def entry_angle_deg(tangent: NDArray[np.float64], outward_normal: NDArray[np.float64]) -> float:
    """Angle (deg) between the needle's direction and the inward normal: 0 = perpendicular entry."""
    cosine = float(np.clip(-tangent @ outward_normal / np.linalg.norm(tangent), -1.0, 1.0))
    return math.degrees(math.acos(cosine))
