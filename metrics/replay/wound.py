"""The wound's cut face as the replay outlines it: where the incision's edges are in the mesh.

A mesh cut by the vessel generator names its two incision faces' nodes (``wound_a``, ``wound_b``);
a block whose free edge is the wound (the wall-stitch task) has none, and its cut face is the
surface lying in the task's wound plane (:class:`metrics.signals.placement.PlacementTargets`). Either way the
replay draws the outline of those surface triangles, so the edge a trainee bites from is visible.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

PLANE_TOLERANCE_M = 2e-5
"""A node within 20 um of the wound plane lies on the cut face (mesh nodes sit on it exactly)."""


def wound_nodes(mesh, wound_point=None, wound_normal=None) -> NDArray[np.int64]:
    """The nodes of the wound's cut faces: the mesh's ``wound_a``/``wound_b`` node sets, else the
    nodes in the plane through ``wound_point`` with ``wound_normal`` (m); empty when neither is known."""
    sets = getattr(mesh, "node_sets", {}) or {}
    if "wound_a" in sets:
        return np.union1d(sets["wound_a"], sets.get("wound_b", np.zeros(0, dtype=np.int64))).astype(np.int64)
    if wound_point is None or wound_normal is None:
        return np.zeros(0, dtype=np.int64)
    distance = (mesh.points - np.asarray(wound_point)) @ np.asarray(wound_normal, dtype=np.float64)
    return np.flatnonzero(np.abs(distance) < PLANE_TOLERANCE_M).astype(np.int64)


def outline_edges(triangles: NDArray[np.int64], nodes: NDArray[np.int64]) -> NDArray[np.int64]:
    """(E, 2) node pairs outlining the surface ``triangles`` whose three nodes are all in ``nodes``:
    the edges only one such triangle has (a cut face's rim)."""
    inside = np.isin(triangles, nodes).all(axis=1)
    faces = triangles[inside]
    if not len(faces):
        return np.zeros((0, 2), dtype=np.int64)
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    unique, counts = np.unique(edges, axis=0, return_counts=True)
    return unique[counts == 1].astype(np.int64)
