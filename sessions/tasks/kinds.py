"""The kinds of task, one class each: what a task's ``scenario`` names and how its ``parameters`` become
a mesh, its contact candidates and a line saying what the geometry is.

- :class:`WallPatch` (``wall_patch``): a flat block of wall, graded finer over the stitch region;
- :class:`VesselPatch` (``vessel_patch``): an arc of an artery's wall with its arteriotomy (and a
  calcified plaque where the task has one);
- :class:`MeshFile` (``mesh_file``): a wall meshed elsewhere, added with ``tasks add`` (checked again
  each time it is built: the file can be edited by hand after it was added).

A new kind is one class here and one entry in :data:`KINDS`.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from sessions.tasks.spec import TaskSpec
from sessions.tasks.user import check_task_mesh, user_tasks_dir
from sim.errors import VascsimError
from sim.mesh import Calcification, Wound, grid_box_mesh, load_mesh, refined_coordinates, vessel_mesh


class TaskKind(ABC):
    """One kind of task (see the module docstring)."""

    scenario: ClassVar[str]

    @abstractmethod
    def mesh(self, spec: TaskSpec):
        """The task's tetrahedral mesh (:class:`sim.mesh.TetMesh`, metres)."""

    @abstractmethod
    def stitch_region_nodes(self, spec: TaskSpec, mesh) -> NDArray[np.int64]:
        """The surface nodes of the task's stitch region: the contact candidates."""

    @abstractmethod
    def geometry(self, spec: TaskSpec) -> str:
        """The geometry in a line, in millimetres, with what holds it."""

    def check(self, spec: TaskSpec, mesh) -> None:
        """Refuse a mesh the task cannot run on (nothing to check for a built-in kind)."""
        return None  # a built-in kind builds its own mesh from checked parameters


class WallPatch(TaskKind):
    """A flat patch of wall: ``stitch_cell_m`` cells over the stitch region (x and y) and through the
    wall, graded to ``cell_m`` elsewhere, so the needle's force kernel spans 3 cells."""

    scenario = "wall_patch"

    def mesh(self, spec: TaskSpec):
        p = spec.parameters
        (length, width, thickness), coarse, fine = p.size_m, p.cell_m, p.stitch_cell_m
        (x0, x1), (y0, y1) = p.stitch_region_m
        return grid_box_mesh(
            refined_coordinates(length, coarse, fine, x0, x1),
            refined_coordinates(width, coarse, fine, y0, y1),
            refined_coordinates(thickness, coarse, fine, 0.0, thickness),
        )

    def stitch_region_nodes(self, spec: TaskSpec, mesh) -> NDArray[np.int64]:
        points = mesh.points[mesh.surface_nodes]
        (x0, x1), (y0, y1) = spec.parameters.stitch_region_m
        inside = (points[:, 0] >= x0 - 1e-9) & (points[:, 0] <= x1 + 1e-9)
        inside &= (points[:, 1] >= y0 - 1e-9) & (points[:, 1] <= y1 + 1e-9)
        return mesh.surface_nodes[inside]

    def geometry(self, spec: TaskSpec) -> str:
        size = " x ".join(f"{1e3 * v:g}" for v in spec.parameters.size_m)
        return f"{size} mm patch, held on {_held(spec)}"


class VesselPatch(TaskKind):
    """An arc of an artery's wall with its arteriotomy, at uniform divisions (the stitch region: an
    angle and z range of the adventitia)."""

    scenario = "vessel_patch"

    def mesh(self, spec: TaskSpec):
        p = spec.parameters
        wound, plaque = p.wound, p.calcification
        return vessel_mesh(
            inner_radius=p.inner_radius_m,
            wall_thickness=p.wall_m,
            length=p.length_m,
            arc_deg=p.arc_deg,
            circumferential_divisions=p.divisions[0],
            radial_divisions=p.divisions[1],
            axial_divisions=p.divisions[2],
            wound=Wound(wound.angle_deg, *wound.z_m, gap=wound.gap_m),
            calcification=None
            if plaque is None
            else Calcification(tuple(plaque.angle_deg), tuple(plaque.z_m), tuple(plaque.layers)),
        )

    def stitch_region_nodes(self, spec: TaskSpec, mesh) -> NDArray[np.int64]:
        points = mesh.points[mesh.surface_nodes]
        region = spec.parameters.stitch_region
        angle = np.degrees(np.arctan2(points[:, 1], points[:, 0]))
        (a0, a1), (z0, z1) = region.angle_deg, region.z_m
        inside = (angle >= a0) & (angle <= a1) & (points[:, 2] >= z0 - 1e-9) & (points[:, 2] <= z1 + 1e-9)
        outer = np.isin(mesh.surface_nodes, mesh.node_sets["outer"])
        return mesh.surface_nodes[inside & outer]

    def geometry(self, spec: TaskSpec) -> str:
        p = spec.parameters
        return (
            f"artery r {1e3 * p.inner_radius_m:g} mm, wall {1e3 * p.wall_m:g} mm, "
            f"{1e3 * p.length_m:g} mm long, {p.arc_deg:g} deg patch, held on {_held(spec)}"
        )


class MeshFile(TaskKind):
    """A wall meshed elsewhere (``tasks add``): the file in the task's folder; the contact candidates
    are the outer surface's nodes within ``stitch_radius_m`` of the entry."""

    scenario = "mesh_file"

    def mesh(self, spec: TaskSpec):
        return load_mesh(user_tasks_dir() / spec.name / spec.parameters.mesh_file)

    def stitch_region_nodes(self, spec: TaskSpec, mesh) -> NDArray[np.int64]:
        outer = mesh.node_sets.get("outer", mesh.surface_nodes)
        distance = np.linalg.norm(mesh.points[outer] - np.asarray(spec.entry), axis=1)
        return np.asarray(outer)[distance <= spec.parameters.stitch_radius_m]

    def geometry(self, spec: TaskSpec) -> str:
        where = f"{spec.parameters.mesh_file} in the task's folder"
        return f"a meshed vessel wall ({where}), held on {_held(spec)}"

    def check(self, spec: TaskSpec, mesh) -> None:
        p = spec.parameters
        check_task_mesh(mesh, p.fixed, spec.entry, p.stitch_radius_m)


KINDS: dict[str, TaskKind] = {kind.scenario: kind for kind in (WallPatch(), VesselPatch(), MeshFile())}
"""Every kind of task by the scenario name a task file and the catalog store."""


def kind_of(spec: TaskSpec) -> TaskKind:
    """The kind of ``spec``'s task, or an error naming the task and the kinds there are."""
    kind = KINDS.get(spec.scenario)
    if kind is None:
        raise VascsimError(
            f"task {spec.name!r} is of kind {spec.scenario!r}, which this vascsim cannot build; "
            f"it builds {', '.join(KINDS)}"
        )
    return kind


def _held(spec: TaskSpec) -> str:
    return ", ".join(spec.parameters.fixed)
