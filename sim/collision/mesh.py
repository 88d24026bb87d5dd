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

from sim.collision import _near as near
from sim.collision.grid import PointGrid
from sim.collision.segments import (
    SegmentHits,
    compiled_crossings,
    intersect_pairs,
)
from sim.geometry import ray_triangle_distances
from sim.mesh.tetmesh import TetMesh

NEAR_PADDING = 5e-4
"""near_boxes asks for this much (m) more than the boxes need, so the next FEM steps' boxes (a needle
moves 2-20 um a step at hand speeds) fall inside and reuse the answer."""


class CollisionMesh:
    """Exterior triangles of a tissue mesh with their current corners, normals and boxes.

    valid: optional (F,) mask of triangles the needle may collide with (default all).
    """

    def __init__(self, mesh: TetMesh, valid: ArrayLike | None = None) -> None:
        self.mesh = mesh
        self.triangles = mesh.surface_triangles
        self.valid = np.ones(len(self.triangles), dtype=bool) if valid is None else np.asarray(valid, bool)
        self._valid_ids = np.flatnonzero(self.valid)
        self.edges, self.edge_faces = _edges_of(self.triangles[self._valid_ids], self._valid_ids)
        """(E, 2) node ids of the valid triangles' edges, and (E, 2) the triangles on either side
        (-1 where an edge borders only one): what a needle's body sweeps across between two poses."""
        self._valid_position = np.full(len(self.triangles), -1, dtype=np.int64)
        self._valid_position[self._valid_ids] = np.arange(len(self._valid_ids))
        self._build_trees()
        self.update(mesh.points)

    def update(self, points: NDArray[np.float64]) -> None:
        """Move the collision mesh to new node positions (rest + subordinate-hand displacement).

        Only the triangles on nodes that moved since the last update are recomputed when they are
        under a quarter of the mesh's (a grasp moves every free surface node, ~2,900 on the
        interrupted stitch's patch: the whole recomputation, 1.2 ms an update; 30 nodes: 0.5 ms);
        the result is the full recomputation's, value for value, in new arrays (a cache keyed on
        the corners' identity sees the change)."""
        points = np.array(points, dtype=np.float64)
        previous = getattr(self, "points", None)
        if previous is None or previous.shape != points.shape:
            self._recompute(points, None)
            return
        changed = np.flatnonzero((points != previous).any(axis=1))  # a NaN never equals: changed
        if changed.size == 0:
            self.points = points
            return
        triangles = self._triangles_on(changed)
        self._recompute(points, triangles if 4 * len(triangles) < len(self.triangles) else None, changed)

    def _recompute(
        self,
        points: NDArray[np.float64],
        triangles: NDArray[np.int64] | None,
        changed: NDArray[np.int64] | None = None,
    ) -> None:
        """Corners, normals, boxes and the broad phase's order at ``points``: of every triangle
        (``triangles`` None) or of the listed ones, the others' kept."""
        self.points = points
        if triangles is None:
            self.corners = points[self.triangles]
            self.normals = _unit_normals(self.corners)
            valid = self.corners[self._valid_ids]
            self._lower = np.minimum(np.minimum(valid[:, 0], valid[:, 1]), valid[:, 2])  # elementwise:
            self._upper = np.maximum(np.maximum(valid[:, 0], valid[:, 1]), valid[:, 2])  # not min(axis=1)
            moved = points - self.mesh.points
            self._displaced = np.sqrt(np.einsum("ij,ij->i", moved, moved))
        else:
            corners = points[self.triangles[triangles]]
            self.corners = self.corners.copy()
            self.corners[triangles] = corners
            self.normals = self.normals.copy()
            self.normals[triangles] = _unit_normals(corners)
            rows = self._valid_position[triangles]
            kept = rows >= 0
            self._lower, self._upper = self._lower.copy(), self._upper.copy()
            valid = corners[kept]
            self._lower[rows[kept]] = np.minimum(np.minimum(valid[:, 0], valid[:, 1]), valid[:, 2])
            self._upper[rows[kept]] = np.maximum(np.maximum(valid[:, 0], valid[:, 1]), valid[:, 2])
            moved = points[changed] - self.mesh.points[changed]
            self._displaced = self._displaced.copy()
            self._displaced[changed] = np.sqrt(np.einsum("ij,ij->i", moved, moved))
        lower, upper = self._lower, self._upper
        # Broad phase: valid triangles sorted by their lower x; a query scans only the
        # slice whose lower x lies within [needle min x - widest triangle, needle max x].
        self._order = np.argsort(lower[:, 0], kind="stable")
        self._sorted_ids = self._valid_ids[self._order]
        self._sorted_lower = np.ascontiguousarray(lower[self._order])
        self._sorted_upper = np.ascontiguousarray(upper[self._order])
        self._widest_x = float((upper[:, 0] - lower[:, 0]).max()) if len(lower) else 0.0
        self._near_cache = None  # the last near_boxes query: (centres, padded radii, its answer)
        self._moved = float(self._displaced.max()) if len(self._displaced) else 0.0

    def _triangles_on(self, nodes: NDArray[np.int64]) -> NDArray[np.int64]:
        """The triangles (ids, ascending, each once) with a corner on one of ``nodes``."""
        on = np.zeros(len(self.mesh.points), dtype=bool)
        on[nodes] = True
        return np.flatnonzero(on[self.triangles].any(axis=1))  # one pass: 0.1 ms whatever the count

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

    def near_swept(
        self, before: NDArray[np.float64], after: NDArray[np.float64]
    ) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """:meth:`near_boxes` of the boxes a polyline's segments sweep from ``before`` to ``after``
        ((V, 3) vertices; segment k from vertex k+1 to vertex k). When every box lies inside the
        last query's padded balls its answer holds, which one compiled test says (a needle pressing
        or held in the wall: most steps), without forming the boxes."""
        before, after = (np.ascontiguousarray(v, dtype=np.float64) for v in (before, after))
        cached = self._near_cache
        if cached is not None and len(cached[0]) == len(before) - 1:
            if near.swept_inside(before, after, self._moved, cached[0], cached[1]):
                return cached[2]
        lower = np.minimum(np.minimum(before[1:], before[:-1]), np.minimum(after[1:], after[:-1]))
        upper = np.maximum(np.maximum(before[1:], before[:-1]), np.maximum(after[1:], after[:-1]))
        return self.near_boxes(lower, upper)

    def near_boxes(
        self, lower: NDArray[np.float64], upper: NDArray[np.float64]
    ) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """(valid triangle ids, edge ids) that may reach into any of the boxes ``lower``-``upper``
        (B, 3) (m): those whose centroid (midpoint) lies within a box's half-diagonal plus their own
        reach (and how far the subordinate hand has moved the mesh) of its centre; a superset."""
        _, reach, half = self._trees
        centres = 0.5 * (lower + upper)
        radii = 0.5 * np.sqrt(np.einsum("ij,ij->i", upper - lower, upper - lower)) + self._moved
        cached = self._near_cache
        if cached is not None and len(cached[0]) == len(centres):
            # the boxes still inside the padded balls of the last query: its answer holds
            shift = np.sqrt(np.einsum("ij,ij->i", centres - cached[0], centres - cached[0]))
            if np.all(shift + radii <= cached[1]):
                return cached[2]
        radii = radii + NEAR_PADDING
        triangles, edges = self._grids
        result = (
            self._valid_ids[triangles.within(centres, radii + reach)],
            edges.within(centres, radii + half),
        )
        self._near_cache = (centres, radii, result)
        return result

    def _build_trees(self) -> None:
        """KD-trees and grids of the valid triangles' centroids and the edges' midpoints at rest (built
        once: a deformed mesh pads the queries by how far it moved instead)."""
        from scipy.spatial import cKDTree

        rest = self.mesh.points
        corners = rest[self.triangles[self._valid_ids]]
        centroids = corners.mean(axis=1)
        reach = float(np.linalg.norm(corners - centroids[:, None, :], axis=2).max()) if len(corners) else 0.0
        ends = rest[self.edges]
        half = 0.5 * float(np.linalg.norm(ends[:, 1] - ends[:, 0], axis=1).max()) if len(ends) else 0.0
        self._trees = (cKDTree(centroids), reach, half)  # the tree: nearest_to_surface
        # the broad phase's grids (near_boxes), cells about a triangle across
        self._grids = (PointGrid(centroids, 2 * reach), PointGrid(ends.mean(axis=1), 2 * reach))

    def nearest_to_surface(
        self, points: NDArray[np.float64], within: float, count: int
    ) -> NDArray[np.float64]:
        """Up to ``count`` of ``points`` (N, 3) whose nearest valid triangle centroid lies within
        ``within`` (m), nearest first (a quick measure: what is about to touch the surface)."""
        distance, _ = self._trees[0].query(points, distance_upper_bound=within + self._trees[1])
        close = np.flatnonzero(np.isfinite(distance))
        return points[close[np.argsort(distance[close])][:count]]

    def crossings_among(
        self, start: NDArray[np.float64], end: NDArray[np.float64], triangles: NDArray[np.int64]
    ) -> SegmentHits:
        """Every crossing of segments start -> end (S, 3) with the given triangles (ids)."""
        if len(triangles) == 0 or len(start) == 0:
            return intersect_pairs(start, end, self.corners, np.zeros(0, np.int64), np.zeros(0, np.int64))
        return compiled_crossings(start, end, self.corners, triangles)

    def edges_among(
        self, triangles: NDArray[np.float64], edges: NDArray[np.int64]
    ) -> tuple[NDArray[np.int64], SegmentHits]:
        """The given edges (ids into :attr:`edges`) that pass through given triangles (T, 3, 3) (a needle
        segment's swept path): (the crossing edges' ids, their hits: ``segment`` indexes those ids,
        ``triangle`` the given triangles, ``t`` runs along the edge from its first node)."""
        ends = self.points[self.edges[edges]]
        start, end = ends[:, 0], ends[:, 1]
        if len(edges) == 0:
            return edges, intersect_pairs(start, end, triangles, np.zeros(0, np.int64), np.zeros(0, np.int64))
        hits = compiled_crossings(start, end, triangles, np.arange(len(triangles), dtype=np.int64))
        return edges[hits.segment], hits

    def crossings(self, start: NDArray[np.float64], end: NDArray[np.float64]) -> SegmentHits:
        """Every crossing of segments start -> end (S, 3) with the valid triangles, in no order
        (``entering``: from a triangle's front to its back, i.e. into the tissue)."""
        low_x = min(start[:, 0].min(), end[:, 0].min()) - self._widest_x
        high_x = max(start[:, 0].max(), end[:, 0].max())
        keys = self._sorted_lower[:, 0]
        window = slice(int(np.searchsorted(keys, low_x, "left")), int(np.searchsorted(keys, high_x, "right")))
        boxes = (self._sorted_lower[window], self._sorted_upper[window])
        return compiled_crossings(start, end, self.corners, self._sorted_ids[window], boxes)

    def query(self, vertices: NDArray[np.float64]) -> SegmentHits:
        """Every crossing of a needle polyline (vertices tip first) with the valid triangles.

        Segment k runs from vertex k+1 towards vertex k, i.e. the way the needle
        travels, so ``entering`` means moving into the tissue as the tip advances
        and ``t = 1`` is the tip end. Hits come nearest the tip first; their points
        are ``hits.points(*segment_ends(vertices))``.
        """
        hits = self.crossings(*segment_ends(vertices))
        return hits.take(np.lexsort((-hits.t, hits.segment))) if len(hits) > 1 else hits


def _unit_normals(corners: NDArray[np.float64]) -> NDArray[np.float64]:
    """Unit right-hand normals of triangles (T, 3, 3); zero for a degenerate one."""
    edge1 = corners[:, 1] - corners[:, 0]
    edge2 = corners[:, 2] - corners[:, 0]
    normals = np.cross(edge1, edge2)
    lengths = np.sqrt(np.einsum("ij,ij->i", normals, normals))
    lengths[lengths == 0] = np.inf  # degenerate triangle: zero normal
    return normals / lengths[:, None]


def _edges_of(triangles: NDArray[np.int64], ids: NDArray[np.int64]) -> tuple[NDArray, NDArray]:
    """(E, 2) unique edges (node ids, smaller first) of triangles (F, 3) and (E, 2) the ids of the
    triangles either side (-1 for an open edge)."""
    pairs = np.sort(triangles[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    owners = np.repeat(ids, 3)
    edges, inverse = np.unique(pairs, axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    order = np.argsort(inverse, kind="stable")
    faces = np.full((len(edges), 2), -1, dtype=np.int64)
    counts = np.bincount(inverse, minlength=len(edges))
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    faces[:, 0] = owners[order][starts]
    second = counts >= 2
    faces[second, 1] = owners[order][starts[second] + 1]
    return edges.astype(np.int64), faces


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
