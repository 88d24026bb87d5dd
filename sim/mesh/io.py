"""Reading and writing tetrahedral meshes through meshio (VTU, Gmsh .msh, and more)."""

from __future__ import annotations

import contextlib
import io
import logging
import warnings
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from sim.errors import MeshError
from sim.mesh.generators import orient_positive
from sim.mesh.tetmesh import TetMesh, validate_mesh

REGION_KEYS = ("region", "gmsh:physical", "CellEntityIds", "medit:ref")
NODE_SET_PREFIX = "set:"
MAX_REGION_LABEL = 2**31 - 1  # int32, as the catalogue and the FEM store them


@contextlib.contextmanager
def quiet_reading() -> Iterator[None]:
    """Read a file without the reader's own chatter reaching the user: meshio prints to stdout and
    stderr, VTK's readers log errors (through pyvista, to the root logger) and warn. What went wrong
    is told once, by the MeshError the caller raises; a file that reads well needs no words."""
    vtk_display = None
    try:
        from vtkmodules.vtkCommonCore import vtkObject

        vtk_display = vtkObject.GetGlobalWarningDisplay()
        vtkObject.GlobalWarningDisplayOff()
    except ImportError:  # VTK (pyvista) is a core dependency; meshio alone still reads
        vtkObject = None
    previous = logging.root.manager.disable
    logging.disable(logging.CRITICAL)
    try:
        with (
            warnings.catch_warnings(),
            contextlib.redirect_stdout(io.StringIO()),
            contextlib.redirect_stderr(io.StringIO()),
        ):
            warnings.simplefilter("ignore")
            yield
    finally:
        logging.disable(previous)
        if vtkObject is not None:
            vtkObject.SetGlobalWarningDisplay(vtk_display)


def load_mesh(path: str | Path, reorient: bool = False) -> TetMesh:
    """Load a linear tetrahedral mesh from any format meshio reads.

    Region labels come from the first cell-data array among ``region``,
    ``gmsh:physical``, ``CellEntityIds`` and ``medit:ref``; point-data arrays named
    ``set:<name>`` become node sets. With ``reorient=True`` inverted elements are
    flipped instead of rejected. Nodes used only by non-tetrahedral cells (e.g. a
    Gmsh file's boundary lines) are dropped.
    """
    import meshio

    path = Path(path)
    if not path.is_file():
        raise MeshError(f"mesh file {path} does not exist")
    try:
        with quiet_reading():
            raw = meshio.read(path)
    except (Exception, SystemExit) as error:  # meshio raises many types, and exits on unknown content
        reason = str(error) if not isinstance(error, SystemExit) else "not a readable mesh of this format"
        raise MeshError(f"mesh file {path} could not be read: {reason}") from error
    blocks = [i for i, block in enumerate(raw.cells) if block.type == "tetra"]
    if not blocks:
        kinds = sorted({block.type for block in raw.cells})
        raise MeshError(
            f"mesh file {path} has no linear tetrahedra (cell types: {', '.join(kinds) or 'none'})"
        )
    tets = np.vstack([raw.cells[i].data for i in blocks]).astype(np.int64)
    n_points = len(raw.points)
    bad = (tets < 0) | (tets >= n_points)
    if bad.any():  # before any indexing: -1 would wrap to the last node, N+7 would be an IndexError
        element = int(np.argmax(bad.any(axis=1)))
        raise MeshError(
            f"mesh file {path}: tetrahedron {element} refers to node {int(tets[bad][0])}, but the file "
            f"has nodes 0..{n_points - 1}"
        )
    try:
        regions = _regions(raw, blocks, len(tets))
    except MeshError as error:
        raise MeshError(f"mesh file {path}: {error}") from error
    used, tets = np.unique(tets, return_inverse=True)
    tets = tets.reshape(-1, 4)
    points = np.asarray(raw.points, dtype=np.float64)
    if points.shape[1] == 2:
        raise MeshError(f"mesh file {path} is two-dimensional; tetrahedral meshes need 3-D points")
    points = points[used]
    node_sets = {
        name[len(NODE_SET_PREFIX) :]: np.flatnonzero(_flags(path, name, values, n_points)[used])
        for name, values in raw.point_data.items()
        if name.startswith(NODE_SET_PREFIX)
    }
    if reorient:
        tets = orient_positive(points, tets)
    try:
        validate_mesh(points, tets, regions, node_ids=used)  # messages in the file's own node ids
        return TetMesh(points, tets, regions, node_sets=node_sets)
    except MeshError as error:
        raise MeshError(f"mesh file {path}: {error}") from error


def _flags(path: Path, name: str, values, n_points: int) -> np.ndarray:
    """A node set's point data as membership flags: one finite number per node, non-zero = in."""
    flags = np.asarray(values)
    if flags.ndim == 0 or flags.shape[0] != n_points or not np.issubdtype(flags.dtype, np.number):
        raise MeshError(f"mesh file {path}: point data {name!r} is not one number per node")
    flags = flags.reshape(n_points, -1)[:, 0].astype(np.float64)
    if not np.isfinite(flags).all():
        node = int(np.flatnonzero(~np.isfinite(flags))[0])
        raise MeshError(f"mesh file {path}: point data {name!r} is not a finite number at node {node}")
    return flags != 0


def _regions(raw, blocks: list[int], n_tets: int) -> np.ndarray:
    """The tetrahedra's region labels, checked before the cast to int32 (a NaN or 1e20 label
    became an arbitrary region)."""
    for key in REGION_KEYS:
        if key in raw.cell_data:
            labels = np.concatenate([np.asarray(raw.cell_data[key][i]).ravel() for i in blocks])
            if labels.shape != (n_tets,):
                raise MeshError(f"cell data {key!r} has {labels.size} labels for {n_tets} tetrahedra")
            if not (np.issubdtype(labels.dtype, np.integer) or np.issubdtype(labels.dtype, np.floating)):
                raise MeshError(f"cell data {key!r} holds {labels.dtype} values; region labels are integers")
            values = labels.astype(np.float64)
            with np.errstate(invalid="ignore"):
                bad = ~np.isfinite(values) | (values != np.round(values))
                bad |= (values < 0) | (values > MAX_REGION_LABEL)
            if bad.any():
                element = int(np.flatnonzero(bad)[0])
                raise MeshError(
                    f"tetrahedron {element} has region label {labels[element].item()!r} in {key!r}; "
                    f"region labels are whole numbers 0 to {MAX_REGION_LABEL}"
                )
            return labels.astype(np.int32)
    return np.zeros(n_tets, dtype=np.int32)


def save_mesh(mesh: TetMesh, path: str | Path, file_format: str | None = None) -> Path:
    """Write a mesh (regions as cell data ``region``, node sets as ``set:<name>``)."""
    import meshio

    path = Path(path)
    point_data = {}
    for name, ids in mesh.node_sets.items():
        flags = np.zeros(mesh.n_nodes, dtype=np.uint8)
        flags[ids] = 1
        point_data[NODE_SET_PREFIX + name] = flags
    cell_data = {"region": [mesh.regions.astype(np.int32)]}
    if path.suffix == ".msh" and file_format is None:
        file_format = "gmsh22"
        cell_data = {
            "gmsh:physical": [mesh.regions.astype(np.int32)],
            "gmsh:geometrical": [mesh.regions.astype(np.int32)],
        }
        point_data = {}
    out = meshio.Mesh(mesh.points, [("tetra", mesh.tets)], point_data=point_data, cell_data=cell_data)
    meshio.write(
        path, out, file_format=file_format, binary=False
    ) if file_format == "gmsh22" else meshio.write(path, out, file_format=file_format)
    return path
