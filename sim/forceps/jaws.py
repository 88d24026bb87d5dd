"""The forceps and the tissue their jaws close on.

Two rules pick the grasped nodes around the point of the tissue surface nearest the jaws:

- ``"jaws"`` (default): every free surface node within half the jaw width of that point, on any
  face (the outer wall, the lumen, the cut face of a wound edge): the jaws' footprint, a fixed size
  in millimetres whatever the mesh, so the grasp's force converges as the mesh is refined.
- ``"triangle"``: the nearest triangle's three nodes, each moved by the hand's displacement (the
  source paper's rule for the subordinate hand). Its footprint is one triangle, so the force
  needed to move the tissue falls as the mesh is refined (docs/tissue-model.md measures both).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from sim.collision.mesh import CollisionMesh
from sim.errors import VascsimError

GRASP_RULES = ("jaws", "triangle")


class ForcepsError(VascsimError, ValueError):
    """A forceps parameter is out of range; the message names it and its range."""


@dataclass(frozen=True)
class Forceps:
    """The subordinate hand's atraumatic forceps.

    jaw_width: width of the jaws' tips (m): 1.5 mm, the narrowest common DeBakey atraumatic
        vascular forceps (2.0 and 2.8 mm are also made); the grasped footprint's diameter.
    grasp_reach: the jaws close on tissue when the surface is within this distance (m) of the
        point between their tips; farther, they close on air.
    edge_tear_force: force (N) on the grasped tissue past which the grasp tears the edge and lets
        go: 1.35 N, the suture retention strength of the human internal mammary artery (138 gf,
        Konig et al. 2009, Biomaterials 30:1542), the load at which a bite in that wall tears out.
    rule: ``"jaws"`` or ``"triangle"`` (see the module docstring).
    """

    jaw_width: float = 1.5e-3
    grasp_reach: float = 0.5e-3
    edge_tear_force: float = 1.35
    rule: str = "jaws"

    def __post_init__(self) -> None:
        if not 0.2e-3 <= self.jaw_width <= 5e-3:
            raise ForcepsError(f"jaw_width must be 0.2-5 mm; got {self.jaw_width * 1e3:g} mm")
        if not 0.0 < self.grasp_reach <= 3e-3:
            raise ForcepsError(f"grasp_reach must be in (0, 3] mm; got {self.grasp_reach * 1e3:g} mm")
        if not self.edge_tear_force > 0:
            raise ForcepsError(f"edge_tear_force must be positive (N); got {self.edge_tear_force}")
        if self.rule not in GRASP_RULES:
            raise ForcepsError(f"rule must be one of {', '.join(GRASP_RULES)}; got {self.rule!r}")


def _closest_on_triangles(point: NDArray[np.float64], corners: NDArray[np.float64]) -> NDArray[np.float64]:
    """(T, 3) the point of each triangle (T, 3, 3) nearest ``point`` (Ericson, Real-Time Collision
    Detection 5.1.5, by regions of the triangle, vectorised)."""
    a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
    ab, ac, ap = b - a, c - a, point - a
    d1, d2 = np.einsum("ij,ij->i", ab, ap), np.einsum("ij,ij->i", ac, ap)
    bp, cp = point - b, point - c
    d3, d4 = np.einsum("ij,ij->i", ab, bp), np.einsum("ij,ij->i", ac, bp)
    d5, d6 = np.einsum("ij,ij->i", ab, cp), np.einsum("ij,ij->i", ac, cp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        denominator = 1.0 / (va + vb + vc)
        v, w = vb * denominator, vc * denominator
        out = a + ab * v[:, None] + ac * w[:, None]  # inside the face
        t_ab = d1 / (d1 - d3)
        t_ac = d2 / (d2 - d6)
        t_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
    regions = [
        ((vc <= 0) & (d1 >= 0) & (d3 <= 0), a + ab * t_ab[:, None]),
        ((vb <= 0) & (d2 >= 0) & (d6 <= 0), a + ac * t_ac[:, None]),
        ((va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0), b + (c - b) * t_bc[:, None]),
        ((d6 >= 0) & (d5 <= d6), c),
        ((d3 >= 0) & (d4 <= d3), b),
        ((d1 <= 0) & (d2 <= 0), a),
    ]
    for mask, value in regions:  # vertices last: they take precedence where regions meet
        out[mask] = value[mask]
    return out


def closest_surface_point(
    collision: CollisionMesh, point: NDArray[np.float64], reach: float
) -> tuple[int, NDArray[np.float64]] | None:
    """(triangle, point) of the collision mesh's valid triangles nearest ``point`` (m), as the mesh
    is now (the grasp's own deformation included), or None when none lies within ``reach`` (m)."""
    point = np.asarray(point, dtype=np.float64)
    ids = collision.near_boxes((point - reach)[None, :], (point + reach)[None, :])[0]
    if ids.size == 0:
        return None
    nearest = _closest_on_triangles(point, collision.corners[ids])
    distance = np.linalg.norm(nearest - point, axis=1)
    best = int(np.argmin(distance))
    if distance[best] > reach:
        return None
    return int(ids[best]), nearest[best]


def jaw_nodes(
    collision: CollisionMesh,
    triangle: int,
    point: NDArray[np.float64],
    forceps: Forceps,
    free: NDArray[np.bool_],
) -> NDArray[np.int64]:
    """The surface nodes the jaws hold, closing on ``point`` of ``triangle`` (see the module
    docstring's rules); ``free``: (N,) which nodes the tissue model lets move (clamped ones cannot
    be grasped). Sorted node ids; at least the triangle's free corners."""
    corners = collision.triangles[triangle]
    if forceps.rule == "triangle":
        return np.sort(corners[free[corners]])
    surface = collision.mesh.surface_nodes
    surface = surface[free[surface]]
    distance = np.linalg.norm(collision.points[surface] - point, axis=1)
    within = surface[distance <= 0.5 * forceps.jaw_width]
    return np.union1d(within, corners[free[corners]])
