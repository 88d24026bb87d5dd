"""The tetrahedral mesh container, its validation and its exterior surface.

Conventions: coordinates in metres, node-major arrays, elements as 4 node ids
with positive signed volume ``det[p1 - p0, p2 - p0, p3 - p0] / 6``.
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sim.errors import MeshError

# Faces of a positively oriented tet (a, b, c, d), each ordered so that its
# right-hand normal points out of the element. Face k is opposite local node k.
OUTWARD_FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]], dtype=np.int64)

# Relative to the bounding-box diagonal cubed, below which a tet counts as flat.
ZERO_VOLUME_TOLERANCE = 1e-12


def signed_volumes(points: NDArray[np.float64], tets: NDArray[np.int64]) -> NDArray[np.float64]:
    """Signed volume of every tetrahedron (m^3); positive when correctly oriented."""
    p0 = points[tets[:, 0]]
    edges = points[tets[:, 1:]] - p0[:, None, :]
    return np.linalg.det(edges) / 6.0


def group_rows(keys: NDArray[np.int64]) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Group identical rows of an integer array.

    Returns ``(first, inverse)``: ``first[g]`` is a row index of group ``g`` and
    ``inverse[r]`` the group of row ``r``. Groups are numbered in sorted order.
    """
    order = np.lexsort(keys.T[::-1])
    sorted_keys = keys[order]
    starts = np.ones(len(keys), dtype=bool)
    starts[1:] = np.any(sorted_keys[1:] != sorted_keys[:-1], axis=1)
    group_of_sorted = np.cumsum(starts) - 1
    inverse = np.empty(len(keys), dtype=np.int64)
    inverse[order] = group_of_sorted
    return order[starts], inverse


class TetMesh:
    """A validated linear tetrahedral mesh.

    Parameters
    ----------
    points: (N, 3) node coordinates in metres.
    tets: (M, 4) node ids per element, positively oriented.
    regions: (M,) integer region label per element (default all 0).
    region_names: label -> readable name (e.g. ``{0: "media", 1: "calcified"}``).
    node_sets: named groups of node ids (e.g. ``"bottom"``, ``"outer"``, ``"wound_a"``).
    """

    def __init__(
        self,
        points: ArrayLike,
        tets: ArrayLike,
        regions: ArrayLike | None = None,
        region_names: Mapping[int, str] | None = None,
        node_sets: Mapping[str, ArrayLike] | None = None,
    ) -> None:
        self.points = _frozen(np.array(points, dtype=np.float64))
        self.tets = _frozen(_as_index_array(tets, "mesh elements"))
        if regions is None:
            regions = np.zeros(len(self.tets), dtype=np.int32)
        self.regions = _frozen(np.array(regions, dtype=np.int32))
        self.region_names = dict(region_names or {int(r): f"region{r}" for r in np.unique(self.regions)})
        validate_mesh(self.points, self.tets, self.regions)
        self.node_sets = {
            name: _frozen(_checked_node_set(name, ids, len(self.points)))
            for name, ids in (node_sets or {}).items()
        }

    # -- sizes ---------------------------------------------------------------
    @property
    def n_nodes(self) -> int:
        return len(self.points)

    @property
    def n_elements(self) -> int:
        return len(self.tets)

    def __repr__(self) -> str:
        return (
            f"TetMesh({self.n_nodes} nodes, {self.n_elements} elements, "
            f"{len(self.surface_triangles)} surface triangles, regions {sorted(self.region_names.values())})"
        )

    # -- geometry ------------------------------------------------------------
    @cached_property
    def element_volumes(self) -> NDArray[np.float64]:
        """Volume of each element in m^3 (all positive for a valid mesh)."""
        return _frozen(signed_volumes(self.points, self.tets))

    @property
    def volume(self) -> float:
        """Total volume in m^3."""
        return float(self.element_volumes.sum())

    @cached_property
    def _surface(self) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        faces = self.tets[:, OUTWARD_FACES].reshape(-1, 3)
        first, inverse = group_rows(np.sort(faces, axis=1))
        counts = np.bincount(inverse)
        exterior = first[counts[inverse[first]] == 1]
        exterior.sort()
        return faces[exterior], exterior // 4

    @property
    def surface_triangles(self) -> NDArray[np.int64]:
        """(F, 3) exterior triangles, ordered so the right-hand normal points outward."""
        return self._surface[0]

    @property
    def surface_elements(self) -> NDArray[np.int64]:
        """(F,) the element each exterior triangle belongs to."""
        return self._surface[1]

    @cached_property
    def surface_normals(self) -> NDArray[np.float64]:
        """(F, 3) outward unit normals of the exterior triangles."""
        return _frozen(triangle_normals(self.points, self.surface_triangles))

    @cached_property
    def wound_edge_elements(self) -> NDArray[np.int64]:
        """Sorted ids of the elements under exterior triangles lying wholly on the wound's cut faces
        (node sets ``wound_a``/``wound_b``); empty when the mesh has no wound."""
        sets = [self.node_sets[name] for name in ("wound_a", "wound_b") if name in self.node_sets]
        if not sets:
            return _frozen(np.zeros(0, dtype=np.int64))
        on_edge = np.isin(self.surface_triangles, np.concatenate(sets)).all(axis=1)
        return _frozen(np.unique(self.surface_elements[on_edge]))

    @cached_property
    def surface_nodes(self) -> NDArray[np.int64]:
        """Sorted ids of the nodes on the exterior surface."""
        return _frozen(np.unique(self.surface_triangles))

    @cached_property
    def content_hash(self) -> str:
        """SHA-256 of points, elements and regions: identifies the mesh in caches."""
        digest = hashlib.sha256()
        for array in (self.points, self.tets, self.regions):
            digest.update(str(array.shape).encode())
            digest.update(np.ascontiguousarray(array).tobytes())
        return digest.hexdigest()

    def with_points(self, points: ArrayLike) -> TetMesh:
        """A copy with moved nodes (same elements, regions and node sets), validated again."""
        return TetMesh(points, self.tets, self.regions, self.region_names, self.node_sets)


def triangle_normals(points: NDArray[np.float64], triangles: NDArray[np.int64]) -> NDArray[np.float64]:
    """Unit right-hand normals of triangles (zero vector for a degenerate triangle)."""
    a, b, c = (points[triangles[:, k]] for k in range(3))
    normals = np.cross(b - a, c - a)
    lengths = np.linalg.norm(normals, axis=1, keepdims=True)
    return np.divide(normals, lengths, out=np.zeros_like(normals), where=lengths > 0)


def validate_mesh(
    points: NDArray[np.float64],
    tets: NDArray[np.int64],
    regions: NDArray[np.int32],
    node_ids: NDArray[np.int64] | None = None,
) -> None:
    """Raise :class:`MeshError` naming the first offending element, node or face.

    ``node_ids``: the id each node has where the mesh came from (a file's numbering before its
    unused nodes were dropped), so messages name nodes as the file does."""
    _check_shapes(points, tets, regions)
    ids = np.arange(len(points)) if node_ids is None else np.asarray(node_ids)
    _check_finite(points, ids)
    _check_indices(tets, len(points))
    _check_unused(tets, len(points))
    _check_volumes(points, tets, ids[tets])
    _check_faces_and_surface(ids[tets])


def _check_shapes(points: NDArray, tets: NDArray, regions: NDArray) -> None:
    if points.ndim != 2 or points.shape[1] != 3:
        raise MeshError(f"mesh points must have shape (N, 3); got {points.shape}")
    if tets.ndim != 2 or tets.shape[1] != 4:
        raise MeshError(f"mesh elements must have shape (M, 4) (linear tetrahedra); got {tets.shape}")
    if len(tets) == 0:
        raise MeshError("mesh has no elements")
    if regions.shape != (len(tets),):
        raise MeshError(
            f"mesh regions must have one label per element ({len(tets)}); got shape {regions.shape}"
        )


def _check_finite(points: NDArray, ids: NDArray) -> None:
    bad = np.flatnonzero(~np.isfinite(points).all(axis=1))
    if bad.size:
        raise MeshError(f"mesh point {ids[bad[0]]} is not finite: {tuple(points[bad[0]].tolist())}")


def _check_indices(tets: NDArray, n_points: int) -> None:
    bad = np.argwhere((tets < 0) | (tets >= n_points))
    if bad.size:
        element, corner = bad[0]
        raise MeshError(
            f"mesh element {element} references node {tets[element, corner]}, but the mesh has "
            f"{n_points} nodes (valid ids 0..{n_points - 1})"
        )


def _check_unused(tets: NDArray, n_points: int) -> None:
    used = np.zeros(n_points, dtype=bool)
    used[tets.ravel()] = True
    unused = np.flatnonzero(~used)
    if unused.size:
        more = f" (and {unused.size - 1} more)" if unused.size > 1 else ""
        raise MeshError(f"mesh node {unused[0]} is not used by any element{more}")


def _check_volumes(points: NDArray, tets: NDArray, labelled: NDArray) -> None:
    """``labelled``: the elements' nodes by the ids messages name."""
    volumes = signed_volumes(points, tets)
    diagonal = float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))
    tolerance = ZERO_VOLUME_TOLERANCE * diagonal**3
    flat = np.flatnonzero(np.abs(volumes) <= tolerance)
    if flat.size:
        e = flat[0]
        raise MeshError(f"mesh element {e} has zero volume (nodes {_nodes(labelled[e])})")
    inverted = np.flatnonzero(volumes < 0)
    if inverted.size:
        e = inverted[0]
        raise MeshError(
            f"mesh element {e} is inverted (signed volume {volumes[e]:.3g} m^3; "
            f"nodes {_nodes(labelled[e])}): swap two of its nodes, or load with reorient=True"
        )


def _check_faces_and_surface(tets: NDArray) -> None:
    faces = np.sort(tets[:, OUTWARD_FACES].reshape(-1, 3), axis=1)
    first, inverse = group_rows(faces)
    counts = np.bincount(inverse)
    crowded = np.flatnonzero(counts > 2)
    if crowded.size:
        group = crowded[0]
        owners = np.flatnonzero(inverse == group) // 4
        raise MeshError(
            f"mesh face ({_nodes(faces[first[group]])}) is shared by {counts[group]} elements "
            f"({_nodes(owners)}); a face of a tetrahedral mesh belongs to at most 2"
        )
    exterior = faces[first[counts == 1]]
    edges = np.sort(exterior[:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2), axis=1)
    edge_first, edge_inverse = group_rows(edges)
    edge_counts = np.bincount(edge_inverse)
    bad = np.flatnonzero(edge_counts != 2)
    if bad.size:
        edge = edges[edge_first[bad[0]]]
        raise MeshError(
            f"mesh surface is not manifold: edge ({edge[0]}, {edge[1]}) belongs to "
            f"{edge_counts[bad[0]]} exterior triangles (a closed surface needs exactly 2)"
        )


def _nodes(ids: NDArray) -> str:
    return ", ".join(str(int(i)) for i in ids)


def _as_index_array(values: ArrayLike, name: str) -> NDArray[np.int64]:
    array = np.asarray(values)
    if array.size and not np.issubdtype(array.dtype, np.integer):
        if not np.all(np.isfinite(array)) or np.any(array != np.round(array)):
            raise MeshError(f"{name} must be integer node ids; got dtype {array.dtype}")
    return array.astype(np.int64)


def _checked_node_set(name: str, ids: ArrayLike, n_nodes: int) -> NDArray[np.int64]:
    array = np.unique(_as_index_array(ids, f"node set {name!r}"))
    if array.size and (array[0] < 0 or array[-1] >= n_nodes):
        raise MeshError(f"node set {name!r} has ids outside 0..{n_nodes - 1}")
    return array


def _frozen(array: NDArray) -> NDArray:
    array.flags.writeable = False
    return array
