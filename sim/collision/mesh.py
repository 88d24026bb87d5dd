"""The collision mesh (exterior triangles as the detector sees them) and global CD.

The collision mesh follows the subordinate hand's deformation (updated at
graphics rate, normals recomputed) but not the needle's own deformation of the
tissue: PAPER.md section 7, that delay would cause force discontinuities.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sim.collision.segments import SegmentHits, candidate_pairs, intersect_pairs
from sim.geometry import ray_triangle_distances
from sim.mesh.tetmesh import TetMesh


class CollisionMesh:
    """Exterior triangles of a tissue mesh with their current corners, normals and boxes.

    valid: optional (F,) mask of triangles the needle may collide with (default all).
    """

    def __init__(self, mesh: TetMesh, valid: ArrayLike | None = None) -> None:
        self.mesh = mesh
        self.triangles = mesh.surface_triangles
        self.valid = np.ones(len(self.triangles), dtype=bool) if valid is None else np.asarray(valid, bool)
        self._valid_ids = np.flatnonzero(self.valid)
        self.update(mesh.points)

    def update(self, points: NDArray[np.float64]) -> None:
        """Move the collision mesh to new node positions (rest + subordinate-hand displacement)."""
        self.points = np.array(points, dtype=np.float64)
        self.corners = self.points[self.triangles]
        edge1 = self.corners[:, 1] - self.corners[:, 0]
        edge2 = self.corners[:, 2] - self.corners[:, 0]
        normals = np.cross(edge1, edge2)
        lengths = np.sqrt(np.einsum("ij,ij->i", normals, normals))
        lengths[lengths == 0] = np.inf  # degenerate triangle: zero normal
        self.normals = normals / lengths[:, None]
        c0, c1, c2 = (self.corners[self._valid_ids, k] for k in range(3))
        lower = np.minimum(np.minimum(c0, c1), c2)  # elementwise: far faster than min(axis=1)
        upper = np.maximum(np.maximum(c0, c1), c2)
        # Broad phase: valid triangles sorted by their lower x; a query scans only the
        # slice whose lower x lies within [needle min x - widest triangle, needle max x].
        self._order = np.argsort(lower[:, 0], kind="stable")
        self._sorted_ids = self._valid_ids[self._order]
        self._sorted_lower = np.ascontiguousarray(lower[self._order])
        self._sorted_upper = np.ascontiguousarray(upper[self._order])
        self._widest_x = float((upper[:, 0] - lower[:, 0]).max()) if len(lower) else 0.0

    def deform(self, nodes: NDArray[np.int64], displacement: NDArray[np.float64]) -> None:
        """Rest positions plus a displacement (m) of the given nodes."""
        points = self.mesh.points.copy()
        points[nodes] += displacement
        self.update(points)

    def distance_through(
        self, point: NDArray[np.float64], direction: NDArray[np.float64], entry: int
    ) -> float:
        """Distance (m) from an entry ``point`` on triangle ``entry`` along ``direction`` to the first
        other exterior triangle: the length of a straight path through the tissue (inf if none)."""
        unit = np.asarray(direction, dtype=np.float64)
        unit = unit / np.linalg.norm(unit)
        distances = ray_triangle_distances(np.asarray(point, dtype=np.float64), unit, self.corners)
        distances[entry] = np.inf
        distances[distances < 1e-9] = np.inf  # triangles sharing the entry point
        return float(distances.min()) if distances.size else math.inf

    def query(self, vertices: NDArray[np.float64]) -> SegmentHits:
        """Every crossing of a needle polyline (vertices tip first) with the valid triangles.

        Segment k runs from vertex k+1 towards vertex k, i.e. the way the needle
        travels, so ``entering`` means moving into the tissue as the tip advances
        and ``t = 1`` is the tip end. Hits come nearest the tip first; their points
        are ``hits.points(*segment_ends(vertices))``.
        """
        start, end = segment_ends(vertices)
        low_x = min(start[:, 0].min(), end[:, 0].min()) - self._widest_x
        high_x = max(start[:, 0].max(), end[:, 0].max())
        keys = self._sorted_lower[:, 0]
        window = slice(int(np.searchsorted(keys, low_x, "left")), int(np.searchsorted(keys, high_x, "right")))
        segments, local = candidate_pairs(start, end, self._sorted_lower[window], self._sorted_upper[window])
        hits = intersect_pairs(start, end, self.corners, segments, self._sorted_ids[window][local])
        return hits.take(np.lexsort((-hits.t, hits.segment))) if len(hits) > 1 else hits


def segment_ends(vertices: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(start, end) of a needle's segments, each pointing towards the tip."""
    return vertices[1:], vertices[:-1]


@dataclass(frozen=True)
class TriangleContact:
    """A triangle nominated for local CD, and where on it the needle first touched."""

    triangle: int
    nodes: NDArray[np.int64]
    barycentric: NDArray[np.float64]
    point: NDArray[np.float64]
    normal: NDArray[np.float64]

    @classmethod
    def from_hit(cls, collision: CollisionMesh, hits: SegmentHits, k: int, point: NDArray) -> TriangleContact:
        tri = int(hits.triangle[k])
        return cls(
            tri,
            collision.triangles[tri].copy(),
            hits.barycentric[k].copy(),
            point.copy(),
            collision.normals[tri].copy(),
        )

    def penetration(self, tip: NDArray[np.float64]) -> float:
        """Depth (m) of the tip behind the triangle's plane at nomination (> 0: in contact)."""
        return float((self.point - tip).dot(self.normal))
