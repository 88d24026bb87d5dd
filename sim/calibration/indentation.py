"""Scripted indentation experiments on the tissue model (the paper's Fig. 3 and Table 1)."""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sim.fem import BiphaseParameters, BiphaseTissue
from sim.mesh import TetMesh, box_mesh
from sim.needle import Needle, Pose, rotation_aligning
from sim.needle.interaction import NeedleInteraction
from sim.needle.load import KernelLoad, kernel_factory

# Where the scripted needle touches the top face: barycentric weights on the contact triangle.
NEEDLE_WEIGHTS = (0.5, 0.3, 0.2)


def _plain(result) -> dict[str, object]:
    """A result dataclass as plain JSON values (arrays as lists)."""
    return {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in asdict(result).items()}


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
        return _plain(self)


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
        return _plain(self)


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
    ``normal`` (the same :class:`sim.needle.load.KernelLoad` a first touch builds there)."""
    from types import SimpleNamespace

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


class PressedNeedle:
    """A straight needle held perpendicular to a surface and moved along its normal through the
    runtime's own interaction (the same contact law, speed rule and kernels as a session), for
    loading and unloading experiments. It never pierces or tears (those thresholds are lifted), so
    the elastic law is seen whole.

    ``press_to(depth, speed)`` moves the tip to ``depth`` (m below the surface point) at ``speed``
    (m/s) in FEM steps of at most ``step`` (m) and returns the depths and normal forces (N, the
    tissue pushing the needle out) at each step, the start included.
    """

    def __init__(self, tissue, forces, point: ArrayLike, normal: ArrayLike, step: float = 2e-5) -> None:

        self.normal = np.asarray(normal, dtype=np.float64) / np.linalg.norm(normal)
        self.point = np.asarray(point, dtype=np.float64)
        self.step = step
        lifted = forces.with_(puncture_force=1e9, tear_force=None)
        self.needle = Needle.straight(0.01)
        self.interaction = NeedleInteraction(tissue, self.needle, forces=lifted)
        self.rotation = rotation_aligning([1.0, 0.0, 0.0], -self.normal)
        self.time = 0.0
        self.depth = -1e-4  # start 0.1 mm above the surface
        self.force = self._place(self.depth)

    def _place(self, depth: float) -> float:

        tip = self.point - depth * self.normal
        pose = Pose(tip - self.rotation @ self.needle.vertices[0], self.rotation)
        self.interaction.hold(self.time, pose, True)
        return float(self.interaction.fem_step(self.time).needle_force @ self.normal)

    def press_to(self, depth: float, speed: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        if not speed > 0:
            raise ValueError(f"speed must be positive (m/s); got {speed}")
        count = max(1, int(np.ceil(abs(depth - self.depth) / self.step)))
        levels = np.linspace(self.depth, depth, count + 1)
        dt = abs(depth - self.depth) / speed / count
        forces = [self.force]
        for level in levels[1:]:
            self.time += dt
            forces.append(self._place(float(level)))
        self.depth, self.force = depth, forces[-1]
        return levels, np.array(forces)


@dataclass(frozen=True)
class LoadCycle:
    """A needle pressed to a depth and drawn back at given speeds, through the runtime's contact law.

    depth (m), force (N, normal) per step of the loading then the unloading branch; work_in and
    work_out (J): the work done on the tissue while loading and what it returned while unloading.
    """

    loading_depth: NDArray[np.float64]
    loading_force: NDArray[np.float64]
    unloading_depth: NDArray[np.float64]
    unloading_force: NDArray[np.float64]
    speed_in: float
    speed_out: float

    @property
    def work_in(self) -> float:
        return float(np.trapezoid(self.loading_force, self.loading_depth))

    @property
    def work_out(self) -> float:
        return float(-np.trapezoid(self.unloading_force, self.unloading_depth))

    def as_dict(self) -> dict[str, object]:
        return {**_plain(self), "work_in": self.work_in, "work_out": self.work_out}


def load_cycle(
    tissue, forces, point: ArrayLike, normal: ArrayLike, depth: float, speed_in: float, speed_out: float
) -> LoadCycle:
    """Press a needle from the surface to ``depth`` (m) at ``speed_in`` and draw it back to the
    surface at ``speed_out`` (m/s): both branches and the work in and out."""
    pressed = PressedNeedle(tissue, forces, point, normal)
    pressed.press_to(0.0, speed_in)
    loading = pressed.press_to(depth, speed_in)
    unloading = pressed.press_to(0.0, speed_out)
    return LoadCycle(*loading, *unloading, speed_in, speed_out)
