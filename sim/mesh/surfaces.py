"""A vessel wall meshed from surfaces: the lumen surface a segmentation exports (STL, OBJ, VTK/VTP,
PLY), the outer surface or a wall thickness, tetrahedralised by TetGen (through pyvista's ``tetgen``
wrapper) under a radius-edge and dihedral-angle quality bound.

How the wall is built:

1. The lumen surface is read (millimetres by default: what segmentation tools write), triangulated
   and cleaned; its faces are oriented to point out of the lumen (the surface capped at each open
   end must enclose a positive volume).
2. The outer surface is either given or the lumen surface offset along its vertex normals by the
   wall thickness; an open vessel's ends (boundary loops) are closed by annuli joining each lumen
   loop to its offset, so the wall's boundary is one closed surface.
3. TetGen fills that surface (``-pq``: the input surface kept, every element's radius-edge ratio at
   most ``max_radius_edge``, dihedral angles at least ``min_dihedral_deg``, volume at most that of
   a regular tetrahedron of edge ``max_edge``).
4. Regions: each element's relative depth in the wall (distance to the lumen surface over the sum of
   the distances to both surfaces, at its centroid) names its layer (equal shares, intima innermost,
   as :func:`sim.mesh.vessel_mesh`); elements whose centroid lies in a calcified sphere become region
   ``calcified``. Node sets: ``inner``, ``outer`` and ``end0``, ``end1``, ... (the cut ends).

The mesh's quality is measured, not assumed (:func:`sim.mesh.quality.mesh_quality`).

TetGen is licensed AGPL-3.0 (or commercially by WIAS); the Python wrapper is MIT. vascsim calls it as
a separate library: docs/tissue-model.md says what that means for redistribution.
"""

from __future__ import annotations

import contextlib
import math
import tempfile
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from sim.errors import MeshError
from sim.mesh.generators import default_layer_names
from sim.mesh.io import quiet_reading
from sim.mesh.quality import MeshQuality, mesh_quality
from sim.mesh.tetmesh import OUTWARD_FACES, TetMesh, signed_volumes

UNITS = {"m": 1.0, "mm": 1e-3, "cm": 1e-2, "um": 1e-6}


def read_surface(path: str | Path, units: str = "mm"):
    """A triangulated, cleaned surface (pyvista PolyData) in metres from any file pyvista reads."""
    import pyvista as pv

    path = Path(path)
    if units not in UNITS:
        raise MeshError(f"units must be one of {', '.join(UNITS)}; got {units!r}")
    if not path.is_file():
        raise MeshError(f"surface file {path} does not exist")
    try:
        with quiet_reading():
            surface = pv.read(path)
    except Exception as error:  # VTK's readers raise many types
        raise MeshError(f"surface file {path} could not be read: {error}") from error
    if not isinstance(surface, pv.PolyData):
        surface = surface.extract_surface()
    check_surface(surface, path)  # before any filter or mesher sees it: a NaN crashed TetGen
    surface = surface.triangulate().clean()
    if surface.n_cells == 0:
        raise MeshError(f"surface file {path} has no faces")
    surface.points = np.asarray(surface.points, dtype=np.float64) * UNITS[units]
    return surface


def check_surface(surface, path: str | Path) -> None:
    """MeshError, in one line naming the element, unless every vertex of ``surface`` (pyvista
    PolyData as read) is finite and every face has at least three corners, each an existing vertex."""
    points = np.asarray(surface.points, dtype=np.float64)
    if points.size == 0:
        raise MeshError(f"surface file {path} has no vertices")
    finite = np.isfinite(points).all(axis=1)
    if not finite.all():
        vertex = int(np.flatnonzero(~finite)[0])
        raise MeshError(f"surface file {path}: vertex {vertex} has a coordinate that is not a finite number")
    faces = np.asarray(surface.faces, dtype=np.int64)
    if faces.size and faces.size % 4 == 0 and np.all(faces[::4] == 3):  # all triangles: at once
        corners, sizes = faces.reshape(-1, 4)[:, 1:], None
    else:  # any polygons: walk the cell array
        rows, k = [], 0
        while k < faces.size:
            count = int(faces[k])
            if count < 3 or k + 1 + count > faces.size:
                raise MeshError(
                    f"surface file {path}: face {len(rows)} has {count} corner(s); a face needs 3 or more"
                )
            rows.append(faces[k + 1 : k + 1 + count])
            k += 1 + count
        corners, sizes = (
            (np.concatenate(rows) if rows else np.zeros(0, dtype=np.int64)),
            [len(r) for r in rows],
        )
    bad = (corners < 0) | (corners >= len(points))
    if np.any(bad):
        flat = int(np.flatnonzero(bad.ravel())[0])
        face = flat // 3 if sizes is None else int(np.searchsorted(np.cumsum(sizes), flat, side="right"))
        raise MeshError(
            f"surface file {path}: face {face} names vertex {int(corners.ravel()[flat])}, which does not "
            f"exist (the file has vertices 0 to {len(points) - 1})"
        )


def _triangles(surface) -> NDArray[np.int64]:
    faces = np.asarray(surface.faces).reshape(-1, 4)
    if not np.all(faces[:, 0] == 3):
        raise MeshError("the surface must be triangles")
    return faces[:, 1:].astype(np.int64)


def boundary_loops(triangles: NDArray[np.int64]) -> list[NDArray[np.int64]]:
    """The open boundary's loops, each ordered as its faces wind (edge a -> b of a face)."""
    edges = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    keys = np.sort(edges, axis=1)
    _, inverse, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    if counts.max() > 2:
        raise MeshError("the surface is not a manifold (an edge is shared by more than two faces)")
    following = {int(a): int(b) for a, b in edges[counts[inverse.ravel()] == 1]}
    loops = []
    while following:
        start = next(iter(following))
        loop = [start]
        node = following.pop(start)
        while node != start:
            if node not in following:
                raise MeshError("the surface's open boundary does not close into loops")
            loop.append(node)
            node = following.pop(node)
        loops.append(np.array(loop, dtype=np.int64))
    return loops


def _capped_volume(points: NDArray[np.float64], triangles: NDArray[np.int64], loops) -> float:
    """Signed volume enclosed by the surface with each open loop closed by a fan to its centroid."""
    total = np.einsum(
        "ij,ij->i", points[triangles[:, 0]], np.cross(points[triangles[:, 1]], points[triangles[:, 2]])
    )
    volume = total.sum()
    for loop in loops:
        centre = points[loop].mean(axis=0)
        a, b = points[loop], points[np.roll(loop, -1)]
        # the cap's faces wind opposite to the loop (they meet the surface's faces edge to edge)
        volume += np.einsum("ij,ij->i", np.broadcast_to(centre, a.shape), np.cross(b, a)).sum()
    return float(volume) / 6.0


def vertex_normals(points: NDArray[np.float64], triangles: NDArray[np.int64]) -> NDArray[np.float64]:
    """Area-weighted unit normals at the vertices (faces wound counter-clockwise seen from outside)."""
    face = np.cross(
        points[triangles[:, 1]] - points[triangles[:, 0]], points[triangles[:, 2]] - points[triangles[:, 0]]
    )
    normals = np.zeros_like(points)
    for k in range(3):
        np.add.at(normals, triangles[:, k], face)
    length = np.linalg.norm(normals, axis=1)
    if np.any(length == 0):
        raise MeshError("the surface has vertices with no face area around them")
    return normals / length[:, None]


@dataclass(frozen=True)
class WallSurface:
    """The wall's closed boundary: points, triangles (outward from the wall), and which points are on
    the lumen side (the rest on the outer side); the lumen surface's open loops (the cut ends); for a
    closed lumen, a point inside it (the hole a mesher must leave empty)."""

    points: NDArray[np.float64]
    triangles: NDArray[np.int64]
    inner_points: int
    loops: list[NDArray[np.int64]]
    lumen_point: NDArray[np.float64] | None = None


def wall_surface(inner, thickness: float | None = None, outer=None) -> WallSurface:
    """The closed boundary of the wall between the lumen surface ``inner`` and ``outer`` (or the
    lumen offset by ``thickness``, m). With ``outer`` given the two must both be closed."""
    points = np.asarray(inner.points, dtype=np.float64)
    triangles = _triangles(inner)
    loops = boundary_loops(triangles)
    if _capped_volume(points, triangles, loops) < 0:  # faces toward the lumen: turn them outward
        triangles = triangles[:, ::-1].copy()
        loops = boundary_loops(triangles)
    n = len(points)
    if outer is not None:
        if loops:
            raise MeshError("an outer surface is for a closed lumen surface; an open one takes a thickness")
        outer_points = np.asarray(outer.points, dtype=np.float64)
        outer_triangles = _triangles(outer)
        if boundary_loops(outer_triangles):
            raise MeshError("the outer surface must be closed")
        if _capped_volume(outer_points, outer_triangles, []) < 0:
            outer_triangles = outer_triangles[:, ::-1].copy()
        return WallSurface(
            np.vstack([points, outer_points]),
            np.vstack([triangles[:, ::-1], outer_triangles + n]),
            n,
            [],
            _point_inside(points, triangles),
        )
    if thickness is None or not thickness > 0:
        raise MeshError(f"a wall thickness (m) is needed without an outer surface; got {thickness}")
    offset = points + thickness * vertex_normals(points, triangles)
    parts = [triangles[:, ::-1], triangles + n]  # lumen side faces into the lumen: out of the wall
    for loop in loops:
        a, b = loop, np.roll(loop, -1)
        parts.append(np.stack([a, b, b + n], axis=1))
        parts.append(np.stack([a, b + n, a + n], axis=1))
    return WallSurface(np.vstack([points, offset]), np.vstack(parts), n, loops)


def _point_inside(points: NDArray[np.float64], triangles: NDArray[np.int64]) -> NDArray[np.float64]:
    """A point inside a closed, outward-facing surface: just behind its largest face, checked by the
    surface's winding number (solid angles summed over the faces, 4 pi inside)."""
    a, b, c = (points[triangles[:, k]] for k in range(3))
    normals = np.cross(b - a, c - a)
    areas = np.linalg.norm(normals, axis=1)
    for face in np.argsort(areas)[::-1][:20]:
        step = 0.1 * math.sqrt(areas[face])
        candidate = (a[face] + b[face] + c[face]) / 3 - step * normals[face] / areas[face]
        u, v, w = a - candidate, b - candidate, c - candidate
        lu, lv, lw = (np.linalg.norm(x, axis=1) for x in (u, v, w))
        numerator = np.einsum("ij,ij->i", u, np.cross(v, w))
        denominator = lu * lv * lw + np.einsum("ij,ij->i", u, v) * lw + np.einsum("ij,ij->i", v, w) * lu
        denominator += np.einsum("ij,ij->i", w, u) * lv
        if abs(2 * np.arctan2(numerator, denominator).sum() / (4 * math.pi) - 1) < 0.5:
            return candidate
    raise MeshError(
        "no point inside the lumen surface was found: is it closed and free of self-intersections?"
    )


@dataclass(frozen=True)
class CalcifiedSphere:
    """A calcified patch: the wall's elements whose centroid lies within ``radius`` of ``centre`` (m)."""

    centre: tuple[float, float, float]
    radius: float


MESHERS = ("auto", "tetgen", "tetwild")


@contextlib.contextmanager
def _in_scratch_folder(mesher: str) -> Iterator[None]:
    """Run a mesher in a temporary working directory: TetGen writes the faces it skipped
    (``_skipped.node``/``.face``) and fTetWild a copy of its surface (``__tracked_surface.stl``) into
    the working directory, which must not litter a user's folder (or the repository, under the tests)."""
    with tempfile.TemporaryDirectory(prefix=f"vascsim-{mesher}-") as scratch, contextlib.chdir(scratch):
        yield


def _tetgen(wall: WallSurface, max_edge: float, max_radius_edge: float, min_dihedral_deg: float):
    import tetgen

    mesher = tetgen.TetGen(wall.points, wall.triangles.astype(np.int32))
    if wall.lumen_point is not None:  # a closed lumen is a region of its own: leave it empty
        mesher.add_hole(wall.lumen_point)
    try:
        with _in_scratch_folder("tetgen"):
            points, tets, *_ = mesher.tetrahedralize(
                plc=True,
                quality=True,
                minratio=max_radius_edge,
                mindihedral=min_dihedral_deg,
                fixedvolume=True,
                maxvolume=max_edge**3 / (6.0 * math.sqrt(2.0)),  # a regular tetrahedron of edge max_edge
                optmaxdihedral=165.0,  # TetGen's sliver removal: flips and smoothing toward this bound
                opt_iterations=10,
                quiet=True,
            )
    except RuntimeError as error:
        raise MeshError(f"TetGen could not mesh the wall: {error}") from error
    return np.asarray(points, dtype=np.float64), np.asarray(tets, dtype=np.int64)


def _tetwild(wall: WallSurface, max_edge: float):
    """fTetWild (pytetwild): robust to self-intersecting or degenerate input; its boundary follows
    the input within 1e-3 of the bounding box's diagonal; slower than TetGen."""
    import pytetwild

    scale = 1e3  # fTetWild works in the surface's own units: millimetres keep its tolerances sensible
    with _in_scratch_folder("tetwild"):
        points, tets = pytetwild.tetrahedralize(
            wall.points * scale, wall.triangles.astype(np.int32), edge_length_abs=max_edge * scale, quiet=True
        )
    return np.asarray(points, dtype=np.float64) / scale, np.asarray(tets, dtype=np.int64)


def mesh_wall(
    wall: WallSurface,
    max_edge: float,
    layer_names: Sequence[str] | None = None,
    calcified: CalcifiedSphere | None = None,
    max_radius_edge: float = 1.5,
    min_dihedral_deg: float = 10.0,
    mesher: str = "auto",
) -> tuple[TetMesh, MeshQuality]:
    """The wall's quality mesh with layers, a calcified region and node sets. ``mesher``: ``tetgen``
    (keeps the input surface exactly, fast), ``tetwild`` (fTetWild: meshes surfaces TetGen refuses,
    self-intersecting or degenerate ones), ``auto`` (TetGen, then fTetWild if TetGen refuses; the
    quality report says which meshed it and why)."""
    if mesher not in MESHERS:
        raise MeshError(f"mesher must be one of {', '.join(MESHERS)}; got {mesher!r}")
    note = ""
    if mesher in ("auto", "tetgen"):
        try:
            points, tets = _tetgen(wall, max_edge, max_radius_edge, min_dihedral_deg)
            return _labelled(wall, points, tets, layer_names, calcified, "TetGen", tolerance=1e-9)
        except MeshError as error:
            if mesher == "tetgen":
                raise
            note = f"fTetWild, as TetGen refused the surface ({error})"
    points, tets = _tetwild(wall, max_edge)
    diagonal = float(np.linalg.norm(np.ptp(wall.points, axis=0)))
    return _labelled(
        wall, points, tets, layer_names, calcified, note or "fTetWild", tolerance=2e-3 * diagonal
    )


def local_order(points: NDArray[np.float64], tets: NDArray[np.int64]) -> tuple[NDArray, NDArray]:
    """The same mesh with its nodes numbered so that neighbours get near numbers (reverse
    Cuthill-McKee on the node graph); the elements keep the mesher's order (sorting them by their
    lowest node as well made loading the 119k-node wall 2.6x slower).

    A mesher numbers the points it inserts in the order it inserted them, scattered over the wall;
    what a contact reads (the rows of K0^-1's columns at the nodes near the needle, the elements
    around it) then lies scattered through memory. In local order it lies in a narrow band: on a
    96k-node wall the live-stress contact start took 3.1 ms at the median and 4.6 ms at p99, where
    the mesher's numbering took 4.2 and 8.0 (docs/benchmarks.md)."""
    import scipy.sparse as sparse
    from scipy.sparse.csgraph import reverse_cuthill_mckee

    n = len(points)
    rows, cols = np.repeat(tets, 4, axis=1).ravel(), np.tile(tets, (1, 4)).ravel()
    graph = sparse.csr_matrix((np.ones(len(rows), dtype=np.int32), (rows, cols)), shape=(n, n))
    order = np.asarray(reverse_cuthill_mckee(graph, symmetric_mode=True), dtype=np.int64)
    number = np.empty(n, dtype=np.int64)
    number[order] = np.arange(n)
    return points[order], number[tets]


def _labelled(wall, points, tets, layer_names, calcified, mesher: str, tolerance: float):
    points, tets = local_order(points, tets)
    flipped = signed_volumes(points, tets) < 0
    tets[flipped] = tets[flipped][:, [0, 2, 1, 3]]
    names = list(layer_names or default_layer_names(3))
    inner, outer = _distances(wall, points[tets].mean(axis=1))
    depth = np.clip(inner / np.maximum(inner + outer, 1e-15), 0.0, 1.0)
    regions = np.minimum((depth * len(names)).astype(np.int32), len(names) - 1)
    region_names = dict(enumerate(names))
    if calcified is not None:
        centroids = points[tets].mean(axis=1)
        inside = np.linalg.norm(centroids - np.asarray(calcified.centre), axis=1) <= calcified.radius
        if not inside.any():
            raise MeshError("the calcified sphere contains no element of the wall")
        regions[inside] = len(names)
        region_names[len(names)] = "calcified"
    mesh = TetMesh(points, tets, regions, region_names, _node_sets(wall, points, tets, tolerance))
    return mesh, replace(mesh_quality(points, tets), mesher=mesher)


def _distances(wall: WallSurface, at: NDArray[np.float64]) -> tuple[NDArray, NDArray]:
    """Unsigned distances (m) from ``at`` to the lumen surface and to the outer surface."""
    import pyvista as pv

    n = wall.inner_points
    lumen = wall.triangles[np.all(wall.triangles < n, axis=1)]
    outside = wall.triangles[np.all(wall.triangles >= n, axis=1)]

    def distance(triangles):
        faces = np.hstack([np.full((len(triangles), 1), 3), triangles]).ravel()
        surface = pv.PolyData(wall.points, faces)
        return np.abs(pv.PolyData(at).compute_implicit_distance(surface)["implicit_distance"])

    return distance(lumen), distance(outside)


def _node_sets(
    wall: WallSurface, points: NDArray[np.float64], tets: NDArray[np.int64], tolerance: float
) -> dict:
    """``inner``, ``outer`` and one ``endK`` per cut end, from the mesh's boundary nodes: on the lumen
    or outer surface when within ``tolerance`` (m) of it; the others (and a cut end's rim) belong to
    the end whose loop is nearest."""

    faces = tets[:, OUTWARD_FACES].reshape(-1, 3)
    keys = np.sort(faces, axis=1)
    _, inverse, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    nodes = np.unique(faces[counts[inverse.ravel()] == 1])
    inner, outer = _distances(wall, points[nodes])
    sets = {"inner": nodes[inner <= tolerance], "outer": nodes[outer <= tolerance]}
    if wall.loops:
        rims = [
            np.concatenate([wall.points[loop], wall.points[loop + wall.inner_points]]) for loop in wall.loops
        ]
        gaps = np.stack(
            [np.min(np.linalg.norm(points[nodes][:, None] - rim[None], axis=2), axis=1) for rim in rims]
        )
        planes = []
        for loop in wall.loops:  # each cut end lies in (about) one plane: its loop's best fit
            ring = wall.points[loop]
            centre = ring.mean(axis=0)
            normal = np.linalg.svd(ring - centre)[2][-1]
            planes.append(np.abs((points[nodes] - centre) @ normal))
        off_plane = np.stack(planes)
        nearest = np.argmin(gaps + off_plane, axis=0)
        on_end = off_plane[nearest, np.arange(len(nodes))] <= max(
            tolerance, 1e-3 * float(np.ptp(wall.points))
        )
        for k in range(len(wall.loops)):
            sets[f"end{k}"] = nodes[(nearest == k) & on_end]
    return sets


def mesh_vessel_surface(
    inner_path: str | Path,
    thickness: float | None = None,
    outer_path: str | Path | None = None,
    max_edge: float = 5e-4,
    units: str = "mm",
    layer_names: Sequence[str] | None = None,
    calcified: CalcifiedSphere | None = None,
    max_radius_edge: float = 1.5,
    min_dihedral_deg: float = 10.0,
    mesher: str = "auto",
) -> tuple[TetMesh, MeshQuality]:
    """The wall of the vessel whose lumen surface is in ``inner_path`` (module docstring)."""
    inner = read_surface(inner_path, units)
    outer = read_surface(outer_path, units) if outer_path is not None else None
    wall = wall_surface(inner, thickness, outer)
    return mesh_wall(wall, max_edge, layer_names, calcified, max_radius_edge, min_dihedral_deg, mesher)
