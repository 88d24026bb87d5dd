"""A uniform grid of fixed points (triangle centroids, edge midpoints at rest) and which of them lie within
a few balls: the continuous collision test's broad phase (:meth:`CollisionMesh.near_boxes`), asked
whenever the needle's swept boxes leave the last answer's padded balls (every step of a needle moving
fast). Compiled (``sim/collision/_grid.c``): a few microseconds where two KD-tree ball queries and their
merging took about a hundred."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from sim.collision import _grid

MAX_CELLS_PER_AXIS = 64
"""The grid's cells are at least 1/64 of the points' largest extent: at most 64^3 cells however small
the requested cell (a table of 2 MB)."""


class PointGrid:
    """Fixed points (N, 3) (m) bucketed in cubic cells of side about ``cell`` (m)."""

    def __init__(self, points: NDArray[np.float64], cell: float) -> None:
        points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        if not np.isfinite(points).all():
            raise ValueError("a point grid needs finite points")
        self.count = len(points)
        lower = points.min(axis=0) if self.count else np.zeros(3)
        extent = points.max(axis=0) - lower if self.count else np.zeros(3)
        self.cell = max(float(cell), float(extent.max()) / MAX_CELLS_PER_AXIS, 1e-12)
        self.dims = np.maximum(np.floor(extent / self.cell).astype(np.int64) + 1, 1)
        self.origin = lower.astype(np.float64)
        index = np.minimum(((points - lower) / self.cell).astype(np.int64), self.dims - 1)
        keys = (index[:, 0] * self.dims[1] + index[:, 1]) * self.dims[2] + index[:, 2]
        order = np.argsort(keys, kind="stable")
        self._points = np.ascontiguousarray(points[order])
        self._ids = order.astype(np.int64)
        self._starts = np.searchsorted(keys[order], np.arange(int(np.prod(self.dims)) + 1)).astype(np.int64)

    def within(self, centres: NDArray[np.float64], radii: NDArray[np.float64]) -> NDArray[np.int64]:
        """Indices of the points within ``radii`` (B,) of ``centres`` (B, 3) (any of them), ascending."""
        found = _grid.within(
            np.ascontiguousarray(centres, dtype=np.float64),
            np.ascontiguousarray(radii, dtype=np.float64),
            self._points,
            self._ids,
            self._starts,
            self.origin,
            self.cell,
            self.dims,
        )
        return np.frombuffer(found, dtype=np.int64)
