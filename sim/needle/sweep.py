"""Continuous collision detection: where a needle moving between two poses first meets the tissue.

Between two FEM steps every point of the needle moves (to first order) in a straight line from
where it was to where it is. The polyline's segments therefore sweep quadrilaterals (each split
into two triangles), and the needle first meets the surface at the earliest of:

- a vertex's path (a straight segment from its old to its new position) crossing a triangle;
- an edge of the surface passing through a segment's swept quadrilateral (the needle's body
  swept across a corner or the rim of a wound, neither end having crossed);
- at the first pose of a run (nothing to sweep from), the polyline crossing a triangle.

Only crossings into the tissue count: a needle drawn out of the wall (its tail after a pull-through)
meets nothing new.

Each is found with the exact segment-triangle test of :mod:`sim.collision.segments`, so a needle
cannot pass through a wall between two steps however fast it moves. The result says when in the
step (``fraction``), which material point of the needle touched (``segment``, ``along``), where on
which triangle, and whether it was moving into the tissue.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from sim.collision import _near as near
from sim.collision.mesh import CollisionMesh


@dataclass(frozen=True)
class Touch:
    """The first meeting of a moving needle with the tissue surface.

    fraction: of the step (0 = the previous pose, 1 = this one) at which they met.
    segment, along: the needle's material point that touched: segment k runs from vertex k+1
        (``along`` 0) to vertex k (``along`` 1); segment 0 is the tip's.
    triangle, barycentric: the surface triangle met and where on it.
    point: the world point (m) on the surface where they met.
    entering: whether that point of the needle was moving into the tissue.
    """

    fraction: float
    segment: int
    along: float
    triangle: int
    barycentric: NDArray[np.float64]
    point: NDArray[np.float64]
    entering: bool

    @property
    def at_tip(self) -> bool:
        """Whether the needle met the surface with its tip segment (the only part that can pierce)."""
        return self.segment == 0


def first_touch(
    collision: CollisionMesh, before: NDArray[np.float64] | None, after: NDArray[np.float64]
) -> Touch | None:
    """The earliest crossing into the tissue of a needle polyline (vertices tip first) moving from
    ``before`` to ``after`` (``before`` None: the polyline at ``after``), or None. Ties go to the
    part nearest the tip."""
    found = touches(collision, before, after)
    return found[0] if found else None


def touches(
    collision: CollisionMesh,
    before: NDArray[np.float64] | None,
    after: NDArray[np.float64],
    known: Callable[[NDArray[np.float64]], NDArray[np.bool_]] | None = None,
) -> list[Touch]:
    """Every crossing into the tissue of the swept needle, earliest first (ties: nearest the tip);
    with ``before`` None, only the polyline's crossing nearest the tip, if it goes in.

    ``known(points)`` (N, 3) -> (N,) says whether a crossing at each point is already accounted for (a
    current contact, the holes the needle made): when every triangle within reach is, there is
    nothing new to find; the surface edges are swept only when the needle's polyline now crosses the
    surface into the tissue somewhere neither a vertex's path nor ``known`` explains, the one case in
    which a segment's middle can have met the surface first."""
    if before is None:  # the crossing nearest the tip, if it goes in (else the tip is already inside)
        candidates = _at_pose(collision, after)[:1]
    elif before is after or np.array_equal(before, after):  # a needle held still crosses nothing new
        return []
    else:
        # what each segment's swept box (its ends before and after the step) may reach
        triangles, edges = collision.near_swept(before, after)
        if len(triangles) == 0 and len(edges) == 0:  # nothing within reach: most steps of a free needle
            return []
        if known is not None and _all_known(collision, triangles, known):
            return []  # only the surface around what the needle already touches (a needle pressing on)
        # one test for both: the vertices' paths (before -> after) and the polyline as it is now
        count = len(after)
        start, end = np.concatenate([before, after[1:]]), np.concatenate([after, after[:-1]])
        hits = collision.crossings_among(start, end, triangles)
        paths = hits.segment < count
        candidates = _vertex_paths(hits.take(np.flatnonzero(paths)), before, after)
        now = hits.take(np.flatnonzero(~paths))
        points = now.points(start, end) if len(now) else np.zeros((0, 3))
        explained = [t.point for t in candidates if t.entering]
        accounted = known(points) if known is not None and len(points) else np.zeros(len(points), dtype=bool)
        unexplained = [
            point
            for point, entering, seen in zip(points, now.entering, accounted, strict=True)
            if entering
            and not seen
            and not any(np.linalg.norm(point - p) <= EXPLAINED_WITHIN for p in explained)
        ]
        if unexplained:
            candidates += _swept_across_edges(collision, before, after, edges)
    return sorted((t for t in candidates if t.entering), key=lambda t: (t.fraction, t.segment, -t.along))


@dataclass(frozen=True)
class KnownBalls:
    """Surface points a needle already accounts for (its current contacts' reach, the holes it made):
    those within ``radii`` (c,) (m) of one of ``centres`` (c, 3). Called with points (N, 3), says
    which are; :func:`touches` asks, compiled, whether every corner of the triangles within reach is."""

    centres: NDArray[np.float64]
    radii: NDArray[np.float64]

    @classmethod
    def of(cls, centres: list, radii: list) -> KnownBalls:
        return cls(np.array(centres, dtype=np.float64).reshape(-1, 3), np.array(radii, dtype=np.float64))

    def __call__(self, points: NDArray[np.float64]) -> NDArray[np.bool_]:
        offsets = np.atleast_2d(points)[:, None, :] - self.centres[None, :, :]
        return (np.einsum("ijk,ijk->ij", offsets, offsets) <= self.radii * self.radii).any(axis=1)


def _all_known(collision: CollisionMesh, triangles: NDArray[np.int64], known: Callable) -> bool:
    """Whether ``known`` accounts for every corner of ``triangles``."""
    if isinstance(known, KnownBalls):
        return near.all_within(collision.corners, triangles, known.centres, known.radii * known.radii)
    return bool(known(collision.corners[triangles].reshape(-1, 3)).all())


EXPLAINED_WITHIN = 2e-3
"""A crossing of the needle's polyline within this distance (m) of a vertex path's crossing is that
crossing, seen along the needle rather than along the path."""


def _material(vertex: int, count: int) -> tuple[int, float]:
    """(segment, along) of needle vertex ``vertex`` of ``count``."""
    return (vertex, 1.0) if vertex < count - 1 else (count - 2, 0.0)


def _vertex_paths(hits, before: NDArray, after: NDArray) -> list[Touch]:
    """Touches from the crossings of the vertices' paths (``hits.segment``: the vertex)."""
    if len(hits) == 0:
        return []
    points = hits.points(before, after)
    result = []
    for k in range(len(hits)):
        segment, along = _material(int(hits.segment[k]), len(after))
        result.append(
            Touch(
                float(hits.t[k]),
                segment,
                along,
                int(hits.triangle[k]),
                hits.barycentric[k].copy(),
                points[k],
                bool(hits.entering[k]),
            )
        )
    return result


def _at_pose(collision: CollisionMesh, vertices: NDArray) -> list[Touch]:
    hits = collision.query(vertices)
    if len(hits) == 0:
        return []
    start, end = vertices[1:], vertices[:-1]
    points = hits.points(start, end)
    return [
        Touch(
            1.0,
            int(hits.segment[k]),
            float(hits.t[k]),
            int(hits.triangle[k]),
            hits.barycentric[k].copy(),
            points[k],
            bool(hits.entering[k]),
        )
        for k in range(len(hits))
    ]


def _swept_across_edges(
    collision: CollisionMesh, before: NDArray, after: NDArray, edges: NDArray[np.int64]
) -> list[Touch]:
    """Surface edges through the quadrilaterals the segments sweep: segment k from (b1 = before[k+1],
    b0 = before[k]) to (a1 = after[k+1], a0 = after[k]) as triangles (b1, b0, a0) and (b1, a0, a1)."""
    b1, b0, a0, a1 = before[1:], before[:-1], after[:-1], after[1:]
    triangles = np.concatenate([np.stack([b1, b0, a0], axis=1), np.stack([b1, a0, a1], axis=1)])
    edges, hits = collision.edges_among(triangles, edges)
    if len(hits) == 0:
        return []
    segments = len(b1)
    result = []
    for k in range(len(hits)):
        swept, (_, w1, w2) = int(hits.triangle[k]), hits.barycentric[k]
        if swept < segments:  # (b1, b0, a0): time from b to a, along from 1-end to 0-end
            segment, fraction, along = swept, w2, w1 + w2
        else:
            segment, fraction, along = swept - segments, w1 + w2, w1
        edge = int(edges[k])
        first, second = collision.edges[edge]
        t = float(hits.t[k])
        point = (1.0 - t) * collision.points[first] + t * collision.points[second]
        moved_from = before[segment + 1] + along * (before[segment] - before[segment + 1])
        moved_to = after[segment + 1] + along * (after[segment] - after[segment + 1])
        motion = moved_to - moved_from
        faces = [f for f in collision.edge_faces[edge] if f >= 0]
        # the face the point moved against (most opposed to its motion): the one it enters through
        face = min(faces, key=lambda f: float(collision.normals[f] @ motion))
        corners = collision.triangles[face]
        barycentric = np.where(corners == first, 1.0 - t, 0.0) + np.where(corners == second, t, 0.0)
        entering = float(collision.normals[face] @ motion) < 0.0
        result.append(Touch(float(fraction), segment, float(along), face, barycentric, point, entering))
    return result


__all__ = ["KnownBalls", "Touch", "first_touch", "touches"]
