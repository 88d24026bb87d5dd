"""Scripted indentation experiments on the tissue model (the paper's Fig. 3 and Table 1)."""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sim.fem import BiphaseParameters, BiphaseTissue
from sim.mesh import TetMesh, box_mesh

# Where the scripted needle touches the top face: barycentric weights on the contact triangle.
NEEDLE_WEIGHTS = (0.5, 0.3, 0.2)


@dataclass(frozen=True)
class IndentationCurve:
    """Force and volume change of the paper's cube pressed by a needle, per strain level.

    strain: indentation strain |d| / depth; forces are the normal reaction (N, positive
    into the tissue); volume changes are relative (0.01 = 1 % increase).
    """

    strain: NDArray[np.float64]
    force_linear: NDArray[np.float64]
    force_biphase: NDArray[np.float64]
    force_biphase_fast: NDArray[np.float64]
    volume_change_linear: NDArray[np.float64]
    volume_change_biphase: NDArray[np.float64]
    precompute_seconds: float
    fast_speed: float

    @property
    def stretch_ratio(self) -> NDArray[np.float64]:
        return 1.0 + self.strain

    def as_dict(self) -> dict[str, object]:
        return {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in asdict(self).items()}


def paper_cube() -> tuple[TetMesh, np.ndarray]:
    """The 10 mm test cube (729 nodes, 3072 elements), held on its bottom face."""
    mesh = box_mesh(0.01, 8)
    return mesh, mesh.node_sets["z0"]


def top_contact_triangle(mesh: TetMesh) -> NDArray[np.int64]:
    """The upward-facing exterior triangle at the centre of the top face."""
    centre = mesh.points.mean(axis=0)
    centre[2] = mesh.points[:, 2].max()
    centroids = mesh.points[mesh.surface_triangles].mean(axis=1)
    upward = mesh.surface_normals[:, 2] > 0.99
    distance = np.where(upward, np.linalg.norm(centroids - centre, axis=1), np.inf)
    return mesh.surface_triangles[int(np.argmin(distance))]


def indentation_curve(
    strains: ArrayLike,
    parameters: BiphaseParameters | None = None,
    fast_speed: float | None = None,
    cache_dir: str | None = None,
    method: str = "exact",
) -> IndentationCurve:
    """Press a needle straight down into the cube's top centre at each strain level.

    Runs the E1-only (linear) model and the biphase model at rest and at
    ``fast_speed`` (default: the critical speed), with full fields for the volume change.
    ``method="superposition"`` uses the paper's plain superposition of per-node solutions.
    """
    mesh, fixed = paper_cube()
    tissue = BiphaseTissue.build(mesh, fixed, parameters)
    start = time.perf_counter()
    tissue.precompute(cache_dir=cache_dir, use_cache=cache_dir is not None)
    seconds = time.perf_counter() - start
    speed = tissue.parameters.critical_speed if fast_speed is None else fast_speed
    triangle = top_contact_triangle(mesh)
    depth = tissue.depth_under(triangle)
    levels = np.asarray(strains, dtype=np.float64)
    rows = {k: [] for k in ("linear", "biphase", "fast", "vol_linear", "vol_biphase")}
    for strain in levels:
        d = np.array([0.0, 0.0, -strain * depth])
        contacts = {int(n): w * d for n, w in zip(triangle, NEEDLE_WEIGHTS, strict=True)}
        linear = tissue.soft.solve(contacts, fields=True, method=method)
        biphase = tissue.solve(contacts, tool_displacement=d, fields=True, method=method)
        fast = tissue.solve(contacts, tool_displacement=d, needle_speed=speed, method=method)
        rows["linear"].append(0.0 - linear.net_force[2])
        rows["biphase"].append(0.0 - biphase.net_force[2])
        rows["fast"].append(0.0 - fast.net_force[2])
        rows["vol_linear"].append(linear.volume_change)
        rows["vol_biphase"].append(biphase.volume_change)
    return IndentationCurve(
        levels,
        *(np.array(rows[k]) for k in ("linear", "biphase", "fast", "vol_linear", "vol_biphase")),
        precompute_seconds=seconds,
        fast_speed=speed,
    )


@dataclass(frozen=True)
class KernelIndentation:
    """A needle pressed straight into a wall through the force kernel, per depth.

    depth (m) along the inward normal; force (N) normal reaction on the needle; soft_share of the
    biphase split; local_stress (Pa); pierce_depth (m): the first depth whose force reaches the
    puncture force (nan if none does); puncture_force (N).
    """

    depth: NDArray[np.float64]
    force: NDArray[np.float64]
    soft_share: NDArray[np.float64]
    local_stress: NDArray[np.float64]
    pierce_depth: float
    puncture_force: float
    kernel_nodes: int

    def as_dict(self) -> dict[str, object]:
        return {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in asdict(self).items()}


def kernel_indentation_curve(
    tissue,
    forces,
    point: ArrayLike,
    normal: ArrayLike,
    depths: ArrayLike,
    wire_radius: float = 1.25e-4,
    needle_speed: float = 0.0,
) -> KernelIndentation:
    """The force-depth curve the runtime's force kernel gives at a surface ``point`` with outward
    ``normal`` (the same :class:`sim.needle_load.KernelLoad` a first touch builds there)."""
    from types import SimpleNamespace

    from sim.needle_load import KernelLoad, kernel_factory

    mesh = tissue.mesh
    n = np.asarray(normal, dtype=np.float64) / np.linalg.norm(normal)
    centroids = mesh.points[mesh.surface_triangles].mean(axis=1)
    triangle = int(np.argmin(np.linalg.norm(centroids - np.asarray(point), axis=1)))
    nodes = mesh.surface_triangles[triangle]
    contact = SimpleNamespace(
        point=np.asarray(point, dtype=np.float64),
        normal=n,
        nodes=nodes,
        barycentric=np.full(3, 1 / 3),
        triangle=triangle,
    )
    load = KernelLoad(tissue, kernel_factory(forces, wire_radius, [contact]))
    stress = load.local_stress(tissue)
    levels = np.asarray(depths, dtype=np.float64)
    force, share, local = [], [], []
    for depth in levels:
        d = (-depth * n)[None, :]
        s = load.soft_share(d, needle_speed)
        kernel_force = load.elastic_forces(d, s)
        force.append(-float(kernel_force.sum(axis=0) @ n))  # the tissue pushes the needle back out
        share.append(s)
        local.append(stress.maximum(kernel_force.reshape(-1)))
    force_array = np.array(force)
    threshold = forces.puncture_force if forces.puncture_force is not None else np.inf
    reached = np.flatnonzero(force_array >= threshold)
    return KernelIndentation(
        levels,
        force_array,
        np.array(share),
        np.array(local),
        float(levels[reached[0]]) if reached.size else float("nan"),
        float(threshold),
        len(load.nodes),
    )
