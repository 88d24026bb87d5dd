"""The subordinate hand's forceps: which tissue the jaws close on, and holding it where the hand
moves it (PAPER.md: the subordinate hand gives access inside the wound's edge)."""

from sim.forceps.grasp import FORCEPS_EVENT_KINDS, ForcepsEvent, ForcepsInteraction, ForcepsStep
from sim.forceps.jaws import Forceps, ForcepsError, closest_surface_point, jaw_nodes

__all__ = [
    "FORCEPS_EVENT_KINDS",
    "Forceps",
    "ForcepsError",
    "ForcepsEvent",
    "ForcepsInteraction",
    "ForcepsStep",
    "closest_surface_point",
    "jaw_nodes",
]
