"""The subordinate hand on the tissue: grasp, move, release, tear (FEM rate).

Closing the jaws within reach of the surface grasps the nodes under them
(:func:`sim.forceps.jaws.jaw_nodes`); from then on each grasped node is held exactly
at the hand's displacement since the grasp (the source paper's rule: the input
displacement applied equally to each grasped node), through the tissue's condensed
compliance (:meth:`sim.fem.TissueModel.prescribed`: f = G_PP^-1 a). With the needle
loading nodes N by f_N at the same time, the grasp's forces are those that keep its
nodes where the hand put them under both loads, f_P = G_PP^-1 (a - G_PN f_N), and the
field is the superposition G[:, N] f_N + G[:, P] f_P: linear superposition, exact for
the given needle forces. (The needle's own law reads the compliance of the tissue
without the grasp; :meth:`sim.fem.TissueModel.solve` with ``prescribed`` is the joint
solve of both as penalty contact and held nodes.) Opening the jaws lets go and the
linear tissue returns to rest. A pull whose force on the tissue passes the forceps'
``edge_tear_force`` tears the grasped edge out of the jaws (``edge_torn``).

The grasp acts on the tissue's base model (the soft phase of a biphase tissue): the
biphase split is the needle's law, driven by the needle's own indentation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from sim.collision.mesh import CollisionMesh
from sim.fem import Tissue
from sim.fem.inverse.condensation import node_dofs
from sim.forceps.jaws import Forceps, closest_surface_point, jaw_nodes

FORCEPS_EVENT_KINDS = ("grasp", "release_grasp", "edge_torn")
PREFETCH_MARGIN = 0.5e-3
"""A surface cell's size (m) on the arteries (0.3-0.5 mm): the grasped triangle's corners lie within it."""


@dataclass(frozen=True)
class ForcepsEvent:
    """A change of the subordinate hand's hold on the tissue: ``grasp``, ``release_grasp``, ``edge_torn``.

    time (s); triangle: the exterior triangle the jaws closed on (-1 when none); detail: a short
    readable note."""

    kind: str
    time: float
    triangle: int = -1
    detail: str = ""
    layer: str = "fem"


@dataclass(frozen=True)
class ForcepsStep:
    """One FEM step of the subordinate hand: the forceps' force on the tissue (3,) N, the grasped
    tissue's displacement (3,) m (zero when nothing is held), the grasped nodes and their forces
    (k, 3) N, and the step's events."""

    force: NDArray[np.float64]
    displacement: NDArray[np.float64]
    nodes: NDArray[np.int64]
    nodal_forces: NDArray[np.float64]
    events: list[ForcepsEvent] = field(default_factory=list)


_NOTHING = np.zeros(0, dtype=np.int64)


class ForcepsInteraction:
    """The subordinate hand's forceps against one tissue: :meth:`hold` at the haptic rate, the
    tissue's answer in :meth:`fem_step`, the collision mesh moved by :meth:`deform_collision` at the
    graphics rate (the paper's design: the needle meets the tissue where the other hand holds it)."""

    def __init__(self, tissue: Tissue, collision: CollisionMesh, forceps: Forceps | None = None) -> None:
        self.tissue = tissue
        self.model = tissue.base
        self.collision = collision
        self.forceps = forceps or Forceps()
        self._free = np.ones(tissue.mesh.n_nodes, dtype=bool)
        self._free[self.model.clamped_nodes] = False
        surface = tissue.mesh.surface_nodes
        self._moving = surface[self._free[surface]]  # the collision mesh's nodes a grasp can move
        self.jaw_point = np.zeros(3)
        """Where the jaws close (m, world): the subordinate device's tool point."""
        self.jaw_closed = False
        self.nodes = _NOTHING
        """The grasped nodes (empty when nothing is held)."""
        self.triangle = -1
        self._anchor = np.zeros(3)  # the jaw point when the grasp closed
        self._handle = None
        self._pending: list[ForcepsEvent] = []
        self._displacement = np.zeros(3)  # the hand's displacement since the grasp, last FEM step
        # per unit displacement of the hand (every grasped node moved alike, so three patterns):
        self._unit_forces = np.zeros((0, 3))  # (3k, 3) the grasp's nodal forces, G_PP^-1 T
        self._unit_surface = np.zeros((0, 3))  # (3S, 3) the free surface's displacement, G_SP G_PP^-1 T
        self._grasped: tuple | None = None  # (nodes, unit forces) of the grasp held
        self._ready: tuple | None = None  # (nodes, handle, unit forces) prepared ahead (see prepare)
        self._unit_surface_of: tuple | None = None  # the grasp _unit_surface belongs to
        self._shown = False  # whether the collision mesh is away from rest
        self._shown_for: tuple | None = None  # (grasp, displacement) the collision mesh shows
        self._against_key, self._against_matrix = b"", np.zeros((0, 0))  # see _against
        self._kernels_for = self._kernels_against = None  # see _against_kernels
        self._kernels_product = np.zeros((0, 0))

    @property
    def prefetch_radius(self) -> float:
        """How far from the open jaws (m) a node may be that closing them now would hold: the reach,
        half the jaws' width and a cell's margin for the triangle's corners (the column prefetcher
        solves these ahead, so a grasp waits for no solve)."""
        return self.forceps.grasp_reach + 0.5 * self.forceps.jaw_width + PREFETCH_MARGIN

    @property
    def grasping(self) -> bool:
        return self.nodes.size > 0

    def hold(self, time: float, jaw_point: NDArray[np.float64], jaw_closed: bool) -> None:
        """The hand's jaw point (m) and jaws at ``time`` (haptic rate): closing within reach of the
        surface grasps, opening lets go; the events come out of the next :meth:`fem_step`."""
        self.jaw_point = np.asarray(jaw_point, dtype=np.float64)
        was_closed, self.jaw_closed = self.jaw_closed, bool(jaw_closed)
        if jaw_closed and not was_closed:
            self._close(time)
        elif was_closed and not jaw_closed and self.grasping:
            self._let_go()
            self._pending.append(ForcepsEvent("release_grasp", time, self.triangle, "jaws opened"))

    def rehearse(self, point: NDArray[np.float64]) -> None:
        """Close and open the jaws at ``point`` with nothing recorded (before a real-time clock starts:
        the grasp's code paths and the linear-algebra routines it calls are warm for the first real
        one); the hand's state is as before."""
        if self.jaw_closed or self.grasping:
            return
        kept = self.jaw_point
        self.hold(0.0, point, True)
        if self.grasping:
            self._against(self.nodes[:1])  # the needle's coupling, too
            self.surface_displacement()
        self.hold(0.0, point, False)
        self.jaw_point, self._pending = kept, []

    def _grasp_of(self, nodes: NDArray[np.int64]) -> tuple:
        """(handle, unit forces (3k, 3)) holding ``nodes``. Only the grasped nodes' own block (3k x 3k):
        the free surface's answer (3S x 3k, milliseconds to gather) is left to the graphics layer,
        which moves the collision mesh."""
        handle = self.model.prescribed(nodes, nodes)
        return handle, handle.forces_of(np.tile(np.eye(3), (nodes.size, 1)))

    def prepare(self) -> None:
        """Graphics layer, jaws open: build the grasp that closing them where they are would make, so
        the FEM step that closes them only checks that the nodes under the jaws are still these
        (exact: the same nodes give the same grasp) and reuses it."""
        under = None if self.jaw_closed else self._under_jaws()
        ready = self._ready
        if under is None or (ready is not None and np.array_equal(ready[0], under[1])):
            return
        nodes = under[1]
        if any(self.model.needs_solve(int(node), full=True) for node in nodes):
            return  # not solved yet (the prefetcher is on it): never a solve in the graphics layer
        self._ready = (nodes, *self._grasp_of(nodes))

    def _under_jaws(self) -> tuple[int, NDArray[np.int64]] | None:
        """(triangle, the nodes closing the jaws now would hold), or None: out of reach of the surface
        (closing on air) or only clamped tissue under them."""
        found = closest_surface_point(self.collision, self.jaw_point, self.forceps.grasp_reach)
        if found is None:
            return None
        nodes = jaw_nodes(self.collision, found[0], found[1], self.forceps, self._free)
        return (found[0], nodes) if nodes.size else None

    def _close(self, time: float) -> None:
        under = self._under_jaws()
        if under is None:
            return  # closed on air, or on clamped tissue only
        triangle, nodes = under
        ready = self._ready  # built by the graphics layer for the nodes under the open jaws, if these
        if ready is not None and np.array_equal(ready[0], nodes):
            handle, self._unit_forces = ready[1], ready[2]
        else:
            handle, self._unit_forces = self._grasp_of(nodes)
        self._grasped = (nodes, self._unit_forces)
        self.nodes, self.triangle, self._anchor, self._handle = nodes, triangle, self.jaw_point.copy(), handle
        self._pending.append(
            ForcepsEvent(
                "grasp",
                time,
                triangle,
                f"{nodes.size} nodes under the {1e3 * self.forceps.jaw_width:.1f} mm jaws "
                f"({self.forceps.rule} rule)",
            )
        )

    def _let_go(self) -> None:
        self.nodes, self._handle, self._displacement, self._grasped = _NOTHING, None, np.zeros(3), None
        self._against_key = b""

    def fem_step(
        self,
        time: float,
        needle_nodes: NDArray[np.int64] | None = None,
        needle_forces: NDArray | None = None,
        kernel_loads: tuple[NDArray, NDArray] | None = None,
    ) -> ForcepsStep:
        """The grasp's forces holding its nodes at the hand's displacement, with the needle's nodal
        forces on the tissue (``needle_nodes``, ``needle_forces`` (n, 3) N) superposed exactly.
        ``kernel_loads``: (M (3n, q), F (q,)) with ``needle_forces`` = M F, the needle's force kernels'
        map and forces: the superposition is then a (3P x q) product a step (G_PP^-1 G_PN M formed
        once per kernel set) instead of (3P x 3n), which read 0.3 MB a step through the wall."""
        events, self._pending = self._pending, []
        if not self.grasping:
            return ForcepsStep(np.zeros(3), np.zeros(3), _NOTHING, np.zeros((0, 3)), events)
        displacement = self.jaw_point - self._anchor
        hand = (self._unit_forces @ displacement).reshape(-1, 3)
        forces = hand
        if kernel_loads is not None and needle_nodes is not None and len(needle_nodes):
            mapped, kernel_forces = kernel_loads
            forces = hand - (self._against_kernels(needle_nodes, mapped) @ kernel_forces).reshape(-1, 3)
        elif needle_nodes is not None and len(needle_nodes):  # what holds the nodes against the needle
            forces = hand - (self._against(needle_nodes) @ np.reshape(needle_forces, -1)).reshape(-1, 3)
        total = forces.sum(axis=0)
        pull = math.sqrt(float(total.dot(total)))  # np.linalg.norm's own arithmetic, without its wrapper
        if pull > self.forceps.edge_tear_force:
            triangle = self.triangle
            self._let_go()
            detail = (
                f"the grasped edge tore out of the jaws at {1e3 * pull:.0f} mN "
                f"(holds up to {1e3 * self.forceps.edge_tear_force:.0f} mN)"
            )
            events.append(ForcepsEvent("edge_torn", time, triangle, detail))
            return ForcepsStep(np.zeros(3), np.zeros(3), _NOTHING, np.zeros((0, 3)), events)
        self._displacement = displacement
        return ForcepsStep(total, displacement, self.nodes, forces, events)

    def _against(self, needle_nodes: NDArray[np.int64]) -> NDArray[np.float64]:
        """G_PP^-1 G_PN: the grasp's nodal forces per unit needle load on ``needle_nodes``, built once
        per needle contact set (the needle's kernel keeps its nodes for many FEM steps)."""
        key = needle_nodes.tobytes()
        if key != self._against_key:
            # G_PN = (G_NP)^T: rows of the grasped nodes' own columns, which the grasp solved whole
            coupling = self.model.columns_at(self.nodes, node_dofs(needle_nodes)).T
            self._against_matrix = self._handle.forces_of(coupling)
            self._against_key = key
        return self._against_matrix

    def _against_kernels(self, needle_nodes: NDArray[np.int64], mapped: NDArray[np.float64]) -> NDArray:
        """G_PP^-1 G_PN M: the grasp's nodal forces per unit force of the needle's kernels whose map
        to nodal forces on ``needle_nodes`` is ``mapped`` (kept while the same map is given)."""
        against = self._against(needle_nodes)
        if self._kernels_for is not mapped or self._kernels_against is not against:
            self._kernels_product = np.ascontiguousarray(against @ mapped)
            self._kernels_for, self._kernels_against = mapped, against
        return self._kernels_product

    def surface_displacement(self) -> tuple[NDArray[np.int64], NDArray[np.float64]] | None:
        """(nodes, displacement (m)) of the tissue's free surface as the hand alone holds it at the last
        FEM step (G[:, P] G_PP^-1 a), or None when nothing is held. The rest of the field, the needle's
        loads on the tissue the grasp holds (G[:, N] f_N - G[:, P] G_PP^-1 G_PN f_N), is the needle's
        own deformation, which the collision mesh does not follow (PAPER.md section 7)."""
        grasped, displacement = self._grasped, self._displacement  # one grasp's, read once (two threads)
        if grasped is None or not self.grasping:
            return None
        if self._unit_surface_of is not grasped:  # first frame of this grasp: G_SP G_PP^-1 T
            nodes, unit_forces = grasped
            self._unit_surface = self.model.columns_at(nodes, node_dofs(self._moving)) @ unit_forces
            self._unit_surface_of = grasped
        return self._moving, (self._unit_surface @ displacement).reshape(-1, 3)

    def deform_collision(self) -> None:
        """Move the collision mesh to where the grasp holds the tissue (graphics rate; back to rest
        once after a release). A hand holding still moves nothing: the mesh is updated only when the
        grasp or the hand's displacement changed since the last frame, and then only the triangles on
        the nodes that moved (0.5 ms an update on the interrupted stitch's patch)."""
        grasped, displacement = self._grasped, self._displacement
        shown = self._shown_for
        if shown is not None and shown[0] is grasped and shown[1] == displacement.tobytes():
            return  # (grasped is never None while _shown_for is set)
        moved = self.surface_displacement()
        if moved is not None:
            self.collision.deform(*moved)
            self._shown = True
            self._shown_for = (grasped, displacement.tobytes())  # the grasp itself kept: identity holds
        elif self._shown:
            self.collision.update(self.collision.mesh.points)
            self._shown, self._shown_for = False, None


def with_grasp(
    loads: tuple[NDArray[np.int64], NDArray[np.float64], float] | None,
    nodes: NDArray[np.int64],
    forces: NDArray[np.float64],
) -> tuple[NDArray[np.int64], NDArray[np.float64], float]:
    """The needle's nodal ``loads`` (or none) and the grasp's (``nodes``, ``forces`` (k, 3) N) as one
    set of loads on distinct nodes (a node both hold carries the sum)."""
    if loads is None:
        return nodes, forces, math.nan
    every, at = np.unique(np.concatenate([loads[0], nodes]), return_inverse=True)
    total = np.zeros((every.size, 3))
    np.add.at(total, at, np.concatenate([loads[1], forces]))
    return every, total, loads[2]
