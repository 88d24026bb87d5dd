"""A tetrahedral mesh's quality, measured element by element: the radius-edge ratio and the dihedral
angles TetGen bounds, and the volumes (docs/tissue-model.md)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike


@dataclass(frozen=True)
class MeshQuality:
    """Shape measures of a tetrahedral mesh: radius-edge ratio (circumradius over the shortest edge;
    0.61 for a regular tetrahedron, large for slivers and needles) and dihedral angles (70.5 deg
    for a regular tetrahedron; small ones stiffen and ill-condition an element)."""

    nodes: int
    elements: int
    radius_edge_median: float
    radius_edge_max: float
    min_dihedral_deg: float
    max_dihedral_deg: float
    below_10_deg: int  # elements with a dihedral angle under 10 deg
    volume: float  # m^3
    mesher: str = ""  # which mesher made it (and why, when the first choice refused the surface)

    def lines(self) -> list[str]:
        return [
            f"{self.nodes} nodes, {self.elements} tetrahedra, wall volume {self.volume * 1e9:.1f} mm^3"
            + (f"; meshed by {self.mesher}" if self.mesher else ""),
            f"radius-edge ratio median {self.radius_edge_median:.2f}, worst {self.radius_edge_max:.2f}"
            " (regular tetrahedron 0.61)",
            f"dihedral angles {self.min_dihedral_deg:.1f} to {self.max_dihedral_deg:.1f} deg"
            f" (regular tetrahedron 70.5); {self.below_10_deg} elements"
            f" ({100 * self.below_10_deg / max(self.elements, 1):.2f} %) with one under 10 deg",
        ]


def mesh_quality(points: ArrayLike, tets: ArrayLike) -> MeshQuality:
    """Radius-edge ratios and dihedral angles of every element (vectorised)."""
    p = np.asarray(points, dtype=np.float64)
    t = np.asarray(tets, dtype=np.int64)
    a, b, c, d = (p[t[:, k]] for k in range(4))
    # circumradius: |(|u|^2 v x w + |v|^2 w x u + |w|^2 u x v)| / (12 V), u, v, w edges from a
    u, v, w = b - a, c - a, d - a
    volume6 = np.einsum("ij,ij->i", u, np.cross(v, w))
    numerator = (
        (u * u).sum(1)[:, None] * np.cross(v, w)
        + (v * v).sum(1)[:, None] * np.cross(w, u)
        + (w * w).sum(1)[:, None] * np.cross(u, v)
    )
    radius = np.linalg.norm(numerator, axis=1) / (2.0 * np.abs(volume6))
    pairs = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]
    corners = np.stack([a, b, c, d], axis=1)
    edges = np.stack([np.linalg.norm(corners[:, i] - corners[:, j], axis=1) for i, j in pairs], axis=1)
    ratio = radius / edges.min(axis=1)
    # dihedral angle at edge (i, j): between the two faces sharing it, from their outward normals
    faces = [(1, 2, 3), (0, 3, 2), (0, 1, 3), (0, 2, 1)]
    normals = []
    for i, j, k in faces:
        n = np.cross(corners[:, j] - corners[:, i], corners[:, k] - corners[:, i])
        normals.append(n / np.linalg.norm(n, axis=1)[:, None])
    angles = []
    for f, g in [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]:
        cosine = np.clip(-np.einsum("ij,ij->i", normals[f], normals[g]), -1.0, 1.0)
        angles.append(np.degrees(np.arccos(cosine)))
    dihedral = np.stack(angles, axis=1)
    return MeshQuality(
        len(p),
        len(t),
        float(np.median(ratio)),
        float(ratio.max()),
        float(dihedral.min()),
        float(dihedral.max()),
        int((dihedral.min(axis=1) < 10.0).sum()),
        float(np.abs(volume6).sum() / 6.0),
    )
