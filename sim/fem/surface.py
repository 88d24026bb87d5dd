"""A tissue mesh's surface geometry: vertex normals, the elements near a point, and the depth of
tissue under each surface node (a ray cast along the inward normal, cached per node).

The biphase model and the force kernel read the depth h under a contact (its indentation strain
is |d| / h); the runtime's prefetcher casts depths ahead of the needle so a contact change rarely
pays for one.
"""

from __future__ import annotations

from collections.abc import Iterable
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sim.errors import ModelError
from sim.geometry import bounding_spheres, ray_may_hit, ray_triangle_distances, vertex_normals
from sim.mesh.tetmesh import TetMesh


class SurfaceGeometry:
    """Normals, element lookup and tissue depth of one mesh (built lazily, cached)."""

    def __init__(self, mesh: TetMesh) -> None:
        self.mesh = mesh
        self._depths: dict[int, float] = {}  # tissue depth (m) under surface nodes, as cast

    @cached_property
    def vertex_normals(self) -> NDArray[np.float64]:
        """(N, 3) area-weighted outward normals at the nodes (zero off the exterior surface)."""
        return vertex_normals(self.mesh.points, self.mesh.surface_triangles)

    @cached_property
    def _element_centre_tree(self):
        from scipy.spatial import cKDTree

        return cKDTree(self.mesh.points[self.mesh.tets].mean(axis=1))

    @cached_property
    def _surface_spheres(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        return bounding_spheres(self.mesh.points[self.mesh.surface_triangles])

    def warm(self) -> None:
        """Build what a first contact needs (normals, the depth cast's bounding spheres, the element
        tree) ahead of it: a few ms at 10k nodes."""
        self.vertex_normals  # noqa: B018 - the cached properties do the work
        self._surface_spheres  # noqa: B018
        self._element_centre_tree  # noqa: B018

    def elements_near(self, points: ArrayLike, radius: float) -> NDArray[np.int64]:
        """Sorted ids of the elements whose centroid lies within ``radius`` (m) of any of ``points``
        ((P, 3), m); the element nearest the first point when none does."""
        tree = self._element_centre_tree
        centres = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        found = tree.query_ball_point(centres, radius)
        near = np.unique(np.concatenate([np.asarray(f, dtype=np.int64) for f in found]))
        return near if near.size else np.array([int(tree.query(centres[0])[1])], dtype=np.int64)

    def tissue_depth(self, node: int) -> float:
        """Thickness of tissue (m) under a surface node, along its inward normal; cached per node."""
        depth = self._depths.get(node)
        if depth is None:
            depth = self._depths[node] = self._cast_depth(node)
        return depth

    def depth_under(self, nodes: NDArray[np.int64]) -> float:
        """Mean tissue depth (m) under contact nodes."""
        return float(np.mean([self.tissue_depth(int(n)) for n in nodes]))

    def knows_depth(self, node: int) -> bool:
        """Whether :meth:`tissue_depth` of ``node`` is cached."""
        return node in self._depths

    def cast_depths(self, nodes: Iterable[int]) -> None:
        """Cast and cache :meth:`tissue_depth` under each node ahead of contact (0.1-0.3 ms a node).
        A node with no depth (off the exterior surface, nothing opposite) is left uncached: a
        contact there raises its error then, as it would have without this call."""
        for node in nodes:
            try:
                self.tissue_depth(int(node))
            except ModelError:
                continue

    def _cast_depth(self, node: int) -> float:
        inward = -self.vertex_normals[node]
        if not np.any(inward):
            raise ModelError(f"node {node} is not on the exterior surface")
        origin = self.mesh.points[node]
        centres, radii = self._surface_spheres
        near = ray_may_hit(origin, inward / np.linalg.norm(inward), centres, radii)
        triangles = self.mesh.surface_triangles[near]
        away = ~np.any(triangles == node, axis=1)
        distances = ray_triangle_distances(origin, inward, self.mesh.points[triangles[away]])
        depth = float(distances.min()) if distances.size else np.inf
        if not np.isfinite(depth):
            raise ModelError(f"no opposite surface found under node {node}")
        return depth
