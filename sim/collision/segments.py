"""Segment-triangle intersection: the paper's three tests, made exact.

For a segment p -> q and a triangle (a, b, c):

1. segment-plane: p and q are not strictly on the same side of the triangle's
   plane, and not both in it (a segment lying in the plane crosses nothing);
2. ray-plane: the crossing parameter t = s_p / (s_p - s_q) along the segment;
3. barycentric: the line pq passes through the closed triangle when the three
   signed volumes (q, c, b, p), (q, a, c, p), (q, b, a, p) share a sign; they are
   proportional to the barycentric coordinates of the crossing point.

Every sign comes from :func:`orient3d`, exact even for degenerate input
(segment in the plane, through an edge or a vertex, zero length, zero-area
triangle): such cases are decided the way exact arithmetic decides them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sim.collision import _crossings
from sim.collision.predicates import ORIENT3D_ACCURACY, ORIENT3D_BOUND, orient3d, orient3d_exact
from sim.errors import VascsimError


class CollisionInputError(VascsimError, ValueError):
    """Segments or triangles of the wrong shape or with non-finite coordinates."""


@dataclass(frozen=True)
class SegmentHits:
    """Every segment-triangle crossing found, one entry per (segment, triangle) pair.

    segment, triangle: (K,) indices into the inputs.
    t: (K,) position of the crossing along its segment, in [0, 1] (0 = start).
    barycentric: (K, 3) coordinates of the crossing point in its triangle (sum 1, >= 0).
    entering: (K,) True where the segment goes from the triangle's front (the side
        its right-hand normal points to) to its back.
    """

    segment: NDArray[np.int64]
    triangle: NDArray[np.int64]
    t: NDArray[np.float64]
    barycentric: NDArray[np.float64]
    entering: NDArray[np.bool_]

    def __len__(self) -> int:
        return len(self.segment)

    def points(self, seg_start: NDArray, seg_end: NDArray) -> NDArray[np.float64]:
        """(K, 3) crossing points on the segments."""
        start, end = seg_start[self.segment], seg_end[self.segment]
        return start + self.t[:, None] * (end - start)

    def take(self, order: NDArray[np.int64]) -> SegmentHits:
        """A reordered or filtered copy."""
        return SegmentHits(
            self.segment[order],
            self.triangle[order],
            self.t[order],
            self.barycentric[order],
            self.entering[order],
        )


def _check(name: str, array: NDArray, shape_tail: tuple[int, ...]) -> NDArray[np.float64]:
    array = np.asarray(array, dtype=np.float64)
    if array.ndim != 1 + len(shape_tail) or array.shape[1:] != shape_tail:
        raise CollisionInputError(
            f"{name} must have shape (n, {', '.join(map(str, shape_tail))}); got {array.shape}"
        )
    if not np.all(np.isfinite(array)):
        raise CollisionInputError(f"{name} must have finite coordinates")
    return array


def bounding_boxes(triangles: NDArray[np.float64]) -> tuple[NDArray, NDArray]:
    """Axis-aligned (T, 3) lower and upper corners of (T, 3, 3) triangles."""
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    return np.minimum(np.minimum(a, b), c), np.maximum(np.maximum(a, b), c)


def candidate_pairs(
    seg_start: NDArray, seg_end: NDArray, lower: NDArray, upper: NDArray
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """(segment, triangle) pairs whose bounding boxes overlap (closed boxes)."""
    seg_lower = np.minimum(seg_start, seg_end)
    seg_upper = np.maximum(seg_start, seg_end)
    (near,) = np.nonzero(((upper >= seg_lower.min(axis=0)) & (lower <= seg_upper.max(axis=0))).all(axis=1))
    if near.size == 0 or len(seg_start) == 0:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty
    below, above = lower[near][None, :, :], upper[near][None, :, :]
    overlap = ((above >= seg_lower[:, None, :]) & (below <= seg_upper[:, None, :])).all(axis=2)
    segments, local = np.nonzero(overlap)
    return segments.astype(np.int64), near[local]


def plane_crossing(vertices: NDArray[np.float64], normal: NDArray[np.float64], point: NDArray[np.float64]):
    """Where the polyline ``vertices`` (V, 3) (a needle, tip first) crosses the plane through ``point``
    with ``normal``: the crossing nearest the point (the first of equals), or None where it does not
    cross (one compiled pass, sim/collision/_crossings.c; float64 C-contiguous arrays)."""
    crossing = _crossings.plane_crossing(vertices, normal, point)
    return None if crossing is None else np.array(crossing)


def compiled_crossings(
    seg_start: NDArray,
    seg_end: NDArray,
    corners: NDArray,
    triangles: NDArray[np.int64],
    boxes: tuple[NDArray, NDArray] | None = None,
) -> SegmentHits:
    """The crossings of segments seg_start -> seg_end (S, 3) with the listed triangles (ids into
    ``corners`` (T, 3, 3)): what candidate_pairs then intersect_pairs give, bit for bit and in their
    order, compiled (sim/collision/_crossings.c); the few pairs floating point is not sure of are
    decided here by intersect_pairs (exact arithmetic) and put in their place. The continuous collision
    test of each FEM step (its NumPy form cost 40-80 us of a step's 140 in array calls on a few dozen
    pairs) and the graphics layer's global test. ``boxes``: the listed triangles' (lower, upper) (n, 3)
    corners where the caller keeps them (read in order, not gathered)."""
    triangles = np.ascontiguousarray(triangles, dtype=np.int64)
    extra = () if boxes is None else tuple(np.ascontiguousarray(b, dtype=np.float64) for b in boxes)
    columns = _crossings.crossings(
        np.ascontiguousarray(seg_start, dtype=np.float64),
        np.ascontiguousarray(seg_end, dtype=np.float64),
        np.ascontiguousarray(corners, dtype=np.float64),
        triangles,
        ORIENT3D_BOUND,
        ORIENT3D_ACCURACY,
        *extra,
    )
    kinds = (np.int64, np.int64, np.float64, np.float64, np.bool_, np.int64, np.int64, np.int64)
    segment, triangle, t, barycentric, entering, place, unsure_segment, unsure_place = (
        np.frombuffer(column, dtype=kind) for column, kind in zip(columns, kinds, strict=True)
    )
    hits = SegmentHits(segment, triangle, t, barycentric.reshape(-1, 3), entering)
    if unsure_segment.size == 0:
        return hits
    # the pairs floating point could not decide, exactly (one call), then every hit in the NumPy path's
    # order; a decided hit's place: its pair's, the hits being a subsequence of the pairs in order
    decided = intersect_pairs(seg_start, seg_end, corners, unsure_segment, triangles[unsure_place])
    pairs = list(
        zip(unsure_segment.tolist(), triangles[unsure_place].tolist(), unsure_place.tolist(), strict=True)
    )
    decided_places, k = [], 0
    for s, tri in zip(decided.segment.tolist(), decided.triangle.tolist(), strict=True):
        while pairs[k][:2] != (s, tri):
            k += 1
        decided_places.append(pairs[k][2])
        k += 1
    places = np.concatenate([place, np.array(decided_places, dtype=np.int64)])
    segments = np.concatenate([hits.segment, decided.segment])
    order = np.argsort(segments * len(triangles) + places, kind="stable")
    return SegmentHits(
        segments[order],
        np.concatenate([hits.triangle, decided.triangle])[order],
        np.concatenate([hits.t, decided.t])[order],
        np.concatenate([hits.barycentric, decided.barycentric])[order],
        np.concatenate([hits.entering, decided.entering])[order],
    )


def intersect_pairs(
    seg_start: NDArray,
    seg_end: NDArray,
    triangles: NDArray,
    segments: NDArray[np.int64],
    tris: NDArray[np.int64],
) -> SegmentHits:
    """Exact crossing test on given (segment, triangle) candidate pairs."""
    if len(segments) == 0:  # most graphics frames of a needle away from the tissue
        return _no_hits()
    p, q = seg_start[segments], seg_end[segments]
    corners = triangles[tris]
    a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
    # The five determinants of every pair in one orient3d call (a needle has few candidate pairs,
    # so a call costs its array operations, not its arithmetic): the two segment ends against
    # the plane, then the three volumes around the line pq.
    values, signs = orient3d(
        np.concatenate((a, a, q, q, q)),
        np.concatenate((b, b, c, a, b)),
        np.concatenate((c, c, b, c, a)),
        np.concatenate((p, q, p, p, p)),
    )
    values, signs = values.reshape(5, -1), signs.reshape(5, -1)
    side_p, side_q, volumes = values[0], values[1], values[2:]
    sign_p, sign_q, around = signs[0], signs[1], signs[2:]
    crossing = (sign_p.astype(np.int16) * sign_q <= 0) & ~((sign_p == 0) & (sign_q == 0))
    inside = (around.min(axis=0) >= 0) | (around.max(axis=0) <= 0)  # the three share a sign
    (chosen,) = np.nonzero(crossing & inside)
    if chosen.size == 0:
        return _no_hits()
    weights = np.abs(volumes[:, chosen].T)
    sp, sq = side_p[chosen], side_q[chosen]
    total = weights.sum(axis=1)
    usable = (total > 0) & np.isfinite(total) & (sp != sq)
    if usable.all():  # the usual case: no masks
        barycentric = weights / total[:, None]
        t = np.minimum(np.maximum(sp / (sp - sq), 0.0), 1.0)  # np.clip, without its wrapper
        return SegmentHits(segments[chosen], tris[chosen], t, barycentric, _entering(sign_p, sign_q, chosen))
    barycentric = np.empty_like(weights)
    t = np.empty_like(sp)
    barycentric[usable] = weights[usable] / total[usable, None]
    t[usable] = np.clip(sp[usable] / (sp[usable] - sq[usable]), 0.0, 1.0)
    for k in np.nonzero(~usable)[0]:  # volumes under/overflowed as floats: redo exactly
        i = chosen[k]
        t[k], barycentric[k] = _exact_crossing(
            seg_start[segments[i]], seg_end[segments[i]], triangles[tris[i]]
        )
    return SegmentHits(segments[chosen], tris[chosen], t, barycentric, _entering(sign_p, sign_q, chosen))


def _entering(sign_p: NDArray, sign_q: NDArray, chosen: NDArray[np.int64]) -> NDArray[np.bool_]:
    """Whether each chosen segment goes from the triangle's front to its back: orient3d(a, b, c, d)
    < 0 when d is on the front (normal) side of abc."""
    sp, sq = sign_p[chosen], sign_q[chosen]
    return (sp < 0) | ((sp == 0) & (sq > 0))


def _no_hits() -> SegmentHits:
    nothing = np.zeros(0, dtype=np.int64)
    return SegmentHits(nothing, nothing, np.zeros(0), np.zeros((0, 3)), np.zeros(0, dtype=bool))


def _exact_crossing(p: NDArray, q: NDArray, triangle: NDArray) -> tuple[float, NDArray[np.float64]]:
    """t and barycentrics of a known crossing, in exact rationals (rare fallback)."""
    a, b, c = triangle
    sp, sq = orient3d_exact(a, b, c, p), orient3d_exact(a, b, c, q)
    weights = [
        abs(orient3d_exact(q, c, b, p)),
        abs(orient3d_exact(q, a, c, p)),
        abs(orient3d_exact(q, b, a, p)),
    ]
    total = sum(weights)
    return float(sp / (sp - sq)), np.array([float(x / total) for x in weights])


def intersect_segments_triangles(
    seg_start: ArrayLike, seg_end: ArrayLike, triangles: ArrayLike
) -> SegmentHits:
    """Every crossing of segments (S, 3) -> (S, 3) with triangles (T, 3, 3).

    A hit is a segment crossing a triangle's plane inside or on the triangle
    (closed: edges and vertices count). A segment lying in the plane, a
    zero-length segment and a zero-area triangle give no hit. Results are sorted
    by segment, then position along it.
    """
    start = _check("seg_start", seg_start, (3,))
    end = _check("seg_end", seg_end, (3,))
    tris = _check("triangles", triangles, (3, 3))
    if start.shape != end.shape:
        raise CollisionInputError(
            f"seg_start and seg_end must have the same shape; got {start.shape} and {end.shape}"
        )
    lower, upper = bounding_boxes(tris)
    segments, candidates = candidate_pairs(start, end, lower, upper)
    hits = intersect_pairs(start, end, tris, segments, candidates)
    return hits.take(np.lexsort((hits.t, hits.segment)))
