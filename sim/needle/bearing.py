"""How the wall bears a needle through it, at the FEM rate: the mixin of
:class:`sim.needle.interaction.NeedleInteraction` that turns where the needle is against where the
wall holds it into forces on the tissue.

- the force kernels (:mod:`sim.needle.load`): a contact set's kernels built when it changes, the
  contact law stepped each FEM step, the live local stress and stretch read from its operator, the
  wall giving way (``tear`` events) and the hold sliding;
- the source paper's barycentric rule (the nominated triangles' nodes driven by their weights);
- the passage's forces along the needle (cutting, friction, the far wall's emergence ramp);
- a released needle settling where the wall no longer pushes it sideways;
- which exterior faces the model's clamps hold (a needle cannot meet them).
"""

from __future__ import annotations

import dataclasses
import math
from time import perf_counter

import numpy as np
from numpy.typing import NDArray

from sim.fem import Tissue
from sim.fem.fields import LocalStress
from sim.needle import Pose, rotation_about
from sim.needle.events import NeedleEvent
from sim.needle.load import KernelLoad, kernel_factory, kernel_step

HELD_EDGE_REACH = 2e-3
"""Exterior triangles this close (m) to a clamped node lie along the model's held edge."""


def held_faces(tissue: Tissue) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """(exterior triangles with every corner clamped, those within :data:`HELD_EDGE_REACH` of a
    clamped node). A needle cannot meet the first: there the model is cut off and held (a vessel
    segment's ends, a patch's held sides) and the real tissue would go on. Along the second the
    needle's body may pass round that edge, into the model's wall from where the real wall goes on."""
    from scipy.spatial import cKDTree

    mesh = tissue.mesh
    clamped = tissue.base.clamped_nodes
    is_clamped = np.zeros(mesh.n_nodes, dtype=bool)
    is_clamped[clamped] = True
    triangles = mesh.surface_triangles
    held = is_clamped[triangles].all(axis=1)
    if clamped.size == 0:
        return held, held.copy()
    centroids = mesh.points[triangles].mean(axis=1)
    distance, _ = cKDTree(mesh.points[clamped]).query(centroids)
    return held, distance <= HELD_EDGE_REACH


def _mean_of(vectors: list[NDArray]) -> NDArray:
    """np.mean(vectors, axis=0) of a few 3-vectors, in its order of additions, without its wrapper."""
    total = vectors[0]
    for vector in vectors[1:]:
        total = total + vector
    return total / len(vectors)


def _cross(a: NDArray, b: NDArray) -> NDArray:
    """np.cross of two 3-vectors, the same products and differences in plain floats (np.cross's
    wrapper cost 45 us a step of a released needle)."""
    (a0, a1, a2), (b0, b1, b2) = a.tolist(), b.tolist()
    return np.array([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0])


class WallBearing:
    """The FEM-rate loads of a needle in or on the wall (see the module docstring); the state it
    reads and sets (contacts, forces, the tissue, the stress operator) is the interaction's."""

    def _settle_released(self, vertices: NDArray, time: float) -> NDArray:
        """A released needle in the wall is held by nothing but the tissue: it moves (rigid) towards
        where the wall's sideways load on it vanishes, the wall's holes where its crossings are, with
        the wall's damped recoil (time constant ``recoil_time``). One crossing: a translation across
        the needle; two: that plus the smallest rotation taking the needle's chord between its
        crossings onto the chord between the holes. Along itself the needle does not move (friction
        holds it). Returns the moved vertices."""
        tangent = self.tip_tangent()
        points, targets = [], []
        for contact in self.contacts:
            point = self._needle_point_at_plane(vertices, contact)
            if point is None or not self._holds(contact, point):
                continue
            offset = point - contact.point
            points.append(point)
            targets.append(point - (offset - offset.dot(tangent) * tangent))
        elapsed = time - self._settled_at
        self._settled_at = time
        if not points or not elapsed > 0:
            return vertices
        share = -math.expm1(-elapsed / self.forces.recoil_time)  # of the way there, this step
        centre, goal = _mean_of(points), _mean_of(targets)
        rotation = np.eye(3)
        if len(points) >= 2:
            chord, wanted = points[-1] - points[0], targets[-1] - targets[0]
            axis = _cross(chord, wanted)
            sine = math.sqrt(float(axis.dot(axis)))  # np.linalg.norm's own arithmetic
            if sine > 1e-15:
                rotation = rotation_about(axis, share * math.atan2(sine, float(chord @ wanted)))
        pose = self.needle_pose
        moved = centre + share * (goal - centre)
        self.needle_pose = Pose(rotation @ (pose.position - centre) + moved, rotation @ pose.rotation)
        return self.needle_vertices()

    def _nodal_stress(self, nodes: NDArray, reactions: NDArray, points: list, displacements: NDArray) -> None:
        """Local stress and stretch of the barycentric rule's nodal forces (operator per contact set)."""
        forces = reactions.reshape(-1)
        if self.live_stress:
            if self._stress is None or self._stress_key != tuple(nodes.tolist()):
                edge = self.tissue.mesh.wound_edge_elements
                self._stress = LocalStress(self.tissue, nodes, np.eye(3 * len(nodes)), points, watched=edge)
                self._stress_key = tuple(nodes.tolist())
            self.local_stress, self.wound_edge_stress, self.stretch = self._stress.measures(forces)
            return
        self.local_stress = self.wound_edge_stress = math.nan
        self.stretch = math.nan if self._stress is None else self._stress.stretch(forces)

    def _axial_forces(self, vertices: NDArray, tangent: NDArray, kernels: int) -> NDArray:
        """(kernels, 3) the passage forces on the tissue along the needle (cutting, friction, the far
        wall's emergence ramp), shared between the kernels the needle crosses."""
        forces = self.forces
        if not forces.resists_passage:
            return np.zeros((kernels, 3))
        entry = self.contacts[0].point
        into = vertices[0] - entry
        depth = math.sqrt(float(into.dot(into)))  # np.linalg.norm's own arithmetic, without its wrapper
        speed = float(np.array(self._tip_velocity).dot(tangent))
        if self.state == "pierced":
            cutting = depth >= self._deepest
            self._deepest = max(self._deepest, depth)
            inside = min(depth, self._wall_path)
            ramp = depth - (self._wall_path - forces.emergence_ramp)
        else:  # through both walls: the shaft spans the wall from entry to exit
            cutting, ramp = False, 0.0
            across = self.contacts[-1].point - entry
            inside = math.sqrt(float(across.dot(across)))
        resistance = forces.axial_resistance(speed, inside, cutting, ramp)
        return (resistance / kernels * tangent)[None, :].repeat(kernels, axis=0)

    def _kernel_load(self, key: tuple) -> KernelLoad:
        """The force kernels of the contact set ``key`` (built, and the build timed, when it changes)."""
        if self._load is None or key != self._load_key:
            began, solved_before = perf_counter(), len(self.tissue.spot_solved)
            chosen = [self.contacts[rank] for _, rank in key]
            tangent = None if key[0][0] == "surface" else self.tip_tangent()
            make = kernel_factory(self.forces, 0.5 * self.needle.wire_diameter, chosen, tangent)
            soft = self.tissue.base
            built = make(soft)
            self._load = KernelLoad(self.tissue, lambda model: built if model is soft else make(model))
            self._stress = self._load.local_stress(self.tissue) if self.live_stress else None
            unsolved = tuple(self.tissue.spot_solved[solved_before:])  # solved here, for this contact
            self.contact_builds.append((self._fem_time, unsolved, perf_counter() - began))
            self._load_key = key
            self._indentation = 0.0
        return self._load

    def _kernel_reactions(
        self, key: tuple, displacements: NDArray, extra_forces: NDArray, surface: NDArray | None = None
    ) -> tuple[NDArray[np.int64], NDArray, list[int]]:
        """(kernel nodes, their forces on the tissue (k, 3), the kernels torn this step) for kernel
        displacements (m, 3) plus explicit forces on the tissue (m, 3) (N); remembers the equivalent
        penalty drive.

        ``surface``: (m, 3) outward normals of a needle pressing on the surface: the contact law of
        :func:`sim.needle.load.kernel_step` (stick-slip, loading-only speed effect, tearing); the
        contact points it moves (slid, torn) are moved here."""
        load = self._kernel_load(key)
        ranks = [rank for _, rank in key]
        step = kernel_step(
            load,
            displacements,
            extra_forces,
            self.tip_speed,
            self._indentation,
            self.forces,
            surface,
            self._tangential_ratio,
        )
        if step.shifts.any():  # a hold slid or tore (rare): move those contacts
            for m, rank in enumerate(ranks):
                if step.shifts[m].any():
                    self._move_contact(rank, step.shifts[m])
        self._indentation, self.soft_share = step.indentation, step.share
        share, kernel_forces, torn = step.share, step.kernel_forces, step.torn
        reactions = load.nodal_forces(kernel_forces)
        self.kernel_loads = (load.soft.force_map, kernel_forces.reshape(-1))
        self.last_contact = load.drive(kernel_forces, share)
        if self._stress is None:
            self.local_stress = self.wound_edge_stress = self.stretch = math.nan
        else:
            # the stretch of the field the display draws: the soft phase's answer to these loads over
            # both phases'
            self.local_stress, self.wound_edge_stress, self.stretch = self._stress.measures(
                kernel_forces.reshape(-1), 1.0 / load.drive_scale(share)
            )
        return load.nodes, reactions, [ranks[m] for m in torn]

    def _move_contact(self, rank: int, shift: NDArray) -> None:
        """The wall's hold on the needle moves by ``shift`` (m): it slid, or the wall tore."""
        contact = self.contacts[rank]
        self.contacts[rank] = dataclasses.replace(contact, point=contact.point + shift)

    def _tear_events(self, time: float, ranks: list[int]) -> list[NeedleEvent]:
        """A ``tear`` event when a crossing first gives way (once per contact or passage)."""
        events = []
        for rank in ranks:
            if rank in self._torn:
                continue
            self._torn.add(rank)
            contact = self.contacts[rank]
            where = "at the surface contact" if self.state == "contact" else "where the needle crosses it"
            events.append(
                NeedleEvent(
                    "tear",
                    time,
                    contact.triangle,
                    tuple(contact.barycentric),
                    tip_speed=self.tip_speed,
                    detail=f"the wall gave way {where} at {1e3 * self.forces.tear_force:.0f} mN",
                )
            )
        return events

    def _reactions(self, nodes: NDArray[np.int64], intended: NDArray, tool_displacement: NDArray) -> NDArray:
        self.last_contact = (nodes, intended)
        key = tuple(nodes.tolist())
        if self._handle is None or key != self._handle_nodes:
            unsolved = tuple(n for n in key if self.tissue.needs_solve(n))
            began = perf_counter()
            self._handle = self.tissue.contact(nodes)
            self.contact_builds.append((self._fem_time, unsolved, perf_counter() - began))
            self._handle_nodes = key
        return self._handle.reaction_forces(intended, tool_displacement, self.tip_speed)
