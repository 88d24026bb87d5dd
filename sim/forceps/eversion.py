"""How far everting a wound's edge turns the wall a needle must enter square.

The forceps take the rim and lift it; the wall beside it turns with it. :func:`wall_turn` measures
that turn where a bite enters, on the collision mesh as the graphics layer moves it (the surface
the needle meets and its entry angle is measured against): what a task that needs the edge everted
asks of the subordinate hand (:class:`sim.needle.reach.WristStop`), and what a scripted hand aims at.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sim.collision.mesh import CollisionMesh
from sim.fem import Tissue
from sim.forceps.grasp import ForcepsInteraction
from sim.forceps.jaws import ForcepsError

ENTRY_PATCH_M = 0.35e-3
"""The wall's normal at an entry is the mean of its outward triangles' normals within this distance."""


class WallTurn(NamedTuple):
    """The wall at a bite's entry with the edge everted: its outward ``normal`` (unit), the angle
    it turned from rest (deg), how far the entry point moved (m) and the forceps' force (N)."""

    normal: NDArray[np.float64]
    turned_deg: float
    entry_moved_m: float
    forceps_force: float


def wall_turn(
    tissue: Tissue,
    rim: ArrayLike,
    lift_direction: ArrayLike,
    lift: float,
    entry: ArrayLike,
    normal: ArrayLike,
) -> WallTurn:
    """The wall at ``entry`` (outward ``normal`` at rest) once the forceps take the rim at ``rim`` and
    lift it ``lift`` (m) along ``lift_direction``."""
    rim, entry = (np.asarray(v, dtype=np.float64) for v in (rim, entry))
    direction, rest = (np.asarray(v, dtype=np.float64) for v in (lift_direction, normal))
    direction, rest = direction / np.linalg.norm(direction), rest / np.linalg.norm(rest)
    collision = CollisionMesh(tissue.mesh)
    centres = collision.corners.mean(axis=1)
    near = (np.linalg.norm(centres - entry, axis=1) < ENTRY_PATCH_M) & (collision.normals @ rest > 0.9)
    if not near.any():
        raise ForcepsError(f"no outward wall within {ENTRY_PATCH_M * 1e3:g} mm of the entry {entry.tolist()}")
    hand = ForcepsInteraction(tissue, collision)
    hand.hold(0.0, rim, True)
    hand.hold(0.1, rim + lift * direction, True)
    step = hand.fem_step(0.1)
    hand.deform_collision()
    turned = collision.normals[near].mean(axis=0)
    turned /= np.linalg.norm(turned)
    moved = collision.corners[near].mean(axis=(0, 1)) - centres[near].mean(axis=0)
    angle = math.degrees(math.acos(float(np.clip(turned @ rest, -1.0, 1.0))))
    return WallTurn(turned, angle, float(np.linalg.norm(moved)), float(np.linalg.norm(step.force)))


__all__ = ["ENTRY_PATCH_M", "WallTurn", "wall_turn"]
