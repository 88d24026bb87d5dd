"""Needle-tissue interaction: contact, piercing, passage through the wall, release and re-grab.

Three entry points, called by the multi-rate loop at their own rates:

- :meth:`NeedleInteraction.hold` (haptic rate): the holder's pose and grip; the
  needle follows a closed grip; released in the wall it settles where the wall
  no longer pushes it sideways (at the FEM rate), released in the air it stays
  where it was; it is re-grabbed when the grip closes near it.
- :meth:`NeedleInteraction.graphics_step` (graphics rate): global CD of the whole
  needle against the collision mesh; promotes the triangle the tip first
  crosses to local CD, detects the exit through the far wall or the wound edge,
  the end of the passage, and implausible hits.
- :meth:`NeedleInteraction.fem_step` (FEM rate): local CD against the
  nominated triangle(s), the contact forces through the tissue model, and the
  piercing decision.

States: ``free`` -> ``contact`` -> ``pierced`` -> ``exited`` -> ``free`` (pulled
through). Every transition is a :class:`NeedleEvent`.

How the needle loads the tissue and what resists it after piercing is set by
:class:`sim.needle.forces.NeedleForces`: by default a mesh-independent force kernel
around the tip with the wire's near field (:mod:`sim.fem.kernel`), a force-based
puncture threshold, then cutting, friction and the far wall's emergence peak along
the needle; ``NeedleForces.paper()`` is the source paper's barycentric rule.

Piercing (angle and grasp in :class:`PiercingRules`): a needle in contact pierces
when its entry angle (tip tangent against the inward surface normal; 0 deg is
perpendicular) is at most ``max_entry_angle_deg`` and the normal force reaches the
puncture force (or, with the paper's rule, the stress at its tip, the normal
reaction over the wire's cross-section, reaches ``puncture_stress``). With the
biphase model a faster needle meets the stiff phase sooner (its strain limit falls
with speed), reaches the puncture threshold at a shallower depth and so pierces
sooner: a decisive needle pierces.

After piercing, the tissue holds the needle where it crosses the entry (and, once
out, the exit) surface: its sideways offset from the entry point loads the wall
there, and along its own axis it meets the passage forces. Levering the needle
instead of rotating it along its curve therefore loads the wall. The class is three parts: this
module's state machine, the graphics-rate tracking (:mod:`sim.needle.passage`) and the FEM-rate
loads (:mod:`sim.needle.bearing`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from sim.collision.mesh import CollisionMesh, TriangleContact
from sim.fem import Tissue
from sim.fem.fields import LocalStress
from sim.needle import Needle, Pose
from sim.needle.bearing import WallBearing, held_faces
from sim.needle.events import (
    EVENT_KINDS,
    NEEDLE_STATES,
    FemStep,
    InteractionError,
    NeedleEvent,
    PiercingRules,
    entry_angle_deg,
)
from sim.needle.forces import NeedleForces
from sim.needle.load import KernelLoad, mindlin_ratio, tissue_poisson_ratio
from sim.needle.passage import HOLE_REACH, NEAR_CONTACT, GraphicsRateTracking
from sim.needle.reach import WristLimit
from sim.needle.sweep import KnownBalls, Touch, touches


def _checked_region_forces(
    default: NeedleForces, given: Mapping[int, NeedleForces], mesh
) -> dict[int, NeedleForces]:
    """Region id -> needle forces, checked against the mesh's regions and the default's load model
    (one force kernel serves every region: the load and kernel radius cannot differ)."""
    known = set(np.unique(mesh.regions).tolist())
    checked = {}
    for region, forces in given.items():
        if int(region) not in known:
            raise InteractionError(f"needle forces given for region {region}, which the mesh does not have")
        if (forces.load, forces.kernel_radius, forces.near_field) != (
            default.load,
            default.kernel_radius,
            default.near_field,
        ):
            raise InteractionError(
                f"region {region}'s needle forces must share the tissue's load model and kernel radius"
            )
        checked[int(region)] = forces
    return checked


class NeedleInteraction(GraphicsRateTracking, WallBearing):
    """State machine of one needle against one tissue (see the module docstring)."""

    def __init__(
        self,
        tissue: Tissue,
        needle: Needle,
        rules: PiercingRules | None = None,
        collision: CollisionMesh | None = None,
        grasp: Pose | None = None,
        forces: NeedleForces | None = None,
        region_forces: Mapping[int, NeedleForces] | None = None,
    ) -> None:
        self.tissue = tissue
        self.needle = needle
        self.rules = rules or PiercingRules()
        self.forces = forces or NeedleForces()
        """The needle forces of the current contact: the entered region's (``region_forces``) or
        the tissue's default."""
        self.default_forces = self.forces
        self.region_forces = _checked_region_forces(self.forces, region_forces or {}, tissue.mesh)
        self._load: KernelLoad | None = None  # the kernels' stiffness for the current contact set
        self._load_key: tuple = ()
        self.soft_share = math.nan
        """The biphase soft share of the last FEM step with the force kernel (1 in a one-phase tissue;
        nan with the barycentric rule, whose drive determines it)."""
        self.local_stress = math.nan
        """Largest von Mises stress (Pa) within 1 mm of the contact at the last FEM step (nan when free)."""
        self.stretch = math.nan
        """The largest stretch (deformed over rest length) of the edges of the elements within 1 mm of
        the contact in the displacement field the display draws, at the last FEM step (nan when free
        or without live stress)."""
        self.wound_edge_stress = math.nan
        """Largest von Mises stress (Pa) of the wound's cut-face elements within 3 mm of the contact
        at the last FEM step (nan when free, without live stress, or with no wound edge near)."""
        self.live_stress = True
        """Whether each FEM step computes the local stress. Its operator is built per contact change
        from rows of the load nodes' whole K0^-1 columns (1-3 ms on the 10k artery once they are
        cached; the real-time runtime's prefetcher solves them ahead of the needle)."""
        self._stress: LocalStress | None = None
        self._stress_key: tuple[int, ...] = ()
        self._overstressed = self._edge_overstressed = False
        self._settled_at = 0.0  # FEM time of the last step that moved a released needle
        self._wall_path = math.inf  # straight-line length through the wall from the entry (m)
        self._deepest = 0.0  # deepest tip depth reached into the wall since piercing (m)
        held, self._at_held_edge = held_faces(tissue)
        self.collision = collision or CollisionMesh(tissue.mesh, ~held)
        self._reaches: list[tuple[TriangleContact, NDArray, float]] = []  # the last few triangle reaches
        self.state = "free"
        self.grasped = True
        self.grasp = grasp or Pose.identity()  # needle frame in the holder frame
        self.needle_pose = Pose.identity()
        self.holder_pose = Pose.identity()
        self.contacts: list[TriangleContact] = []  # nominated triangles (entry, then exit)
        self.last_contact: Sequence[NDArray] | None = None  # (nodes, intended): a pair or a KernelDrive
        self._handle = None
        self._handle_nodes: tuple[int, ...] = ()
        self._fem_time = 0.0
        self.contact_builds: list[tuple[float, tuple[int, ...], float]] = []
        """Each change of contact set: (FEM step time (s), the nodes whose columns it had to solve
        there and then, wall seconds the per-tick handle took to build). Prefetching keeps the
        middle one empty; a node there is a contact change the FEM layer waited on."""
        self._implausible_active: set[tuple[str, int]] = set()
        self.wrist: WristLimit | None = None  # where the task's approach stops the wrist (sim.needle.reach)
        self.kernel_loads: tuple[NDArray, NDArray] | None = None
        self._previous_tip: tuple[float, float, float] | None = None
        self._previous_time = 0.0
        self._tip_velocity = (0.0, 0.0, 0.0)
        self._pose_seen: Pose | None = None
        self._pose_geometry = (np.zeros((0, 3)), np.zeros(3))
        self.tip_speed = 0.0
        self._swept_from: NDArray[np.float64] | None = None  # needle vertices at the last FEM step
        self._touches: list[tuple[int, float]] = []  # per surface contact: the needle's (segment, along)
        self._indentation = 0.0  # largest kernel displacement at the last FEM step (m): loading or not
        self._holes: list[NDArray[np.float64]] = []  # entry and exit of the last passage pulled through
        self._torn: set[int] = set()  # crossings (ranks) that have torn in this contact or passage
        self._tangential_ratio = mindlin_ratio(tissue_poisson_ratio(tissue))
        """Tangential over normal stiffness of the surface contact: Mindlin's flat punch, 2(1-nu)/(2-nu)."""

    @property
    def watched_edge_elements(self) -> NDArray[np.int64]:
        """The wound-edge elements whose stress :attr:`wound_edge_stress` is the largest of (those
        within 3 mm of the current contact; empty when free or without live stress)."""
        if self._stress is None or self.state == "free":
            return np.zeros(0, dtype=np.int64)
        return self._stress.watched

    def forces_at(self, triangle: int) -> NeedleForces:
        """The needle forces of the wall region under surface triangle ``triangle`` (the region of
        the element the face belongs to): puncture, passage and damage follow the region entered."""
        if not self.region_forces:
            return self.default_forces
        mesh = self.tissue.mesh
        region = int(mesh.regions[mesh.surface_elements[triangle]])
        return self.region_forces.get(region, self.default_forces)

    # -- haptic rate ----------------------------------------------------------------
    def hold(self, time: float, holder_pose: Pose, grip_closed: bool) -> list[NeedleEvent]:
        """Update the holder; the needle follows a closed grip. Returns release/regrab events."""
        events: list[NeedleEvent] = []
        self.holder_pose = holder_pose
        if self.grasped and not grip_closed:
            self.grasped = False
            self._settled_at = time  # the wall starts pushing the needle back from here
            detail = f"let go with {NEEDLE_STATES.get(self.state, self.state)}"
            events.append(NeedleEvent("release", time, tip_speed=self.tip_speed, detail=detail))
        elif not self.grasped and grip_closed:
            distance = float(np.min(np.linalg.norm(self.needle_vertices() - holder_pose.position, axis=1)))
            if distance <= self.rules.regrab_distance:
                self.grasp = holder_pose.inverse().compose(self.needle_pose)
                self.grasped = True
                if self.wrist is not None:  # a re-grip at the tip, in the wall, resets the wrist
                    self.wrist.regrip(self.state in ("pierced", "exited"))
                events.append(NeedleEvent("regrab", time, detail=f"{distance * 1e3:.2f} mm from the needle"))
        if self.grasped:
            if self.wrist is not None:  # a cramped approach stops the wrist (sim.needle.reach)
                self.holder_pose, stopped = self.wrist.hold(time, holder_pose, self.grasp)
                events += stopped
            self.needle_pose = self.holder_pose.compose(self.grasp)
        self._track_tip(time)
        return events

    def needle_vertices(self) -> NDArray[np.float64]:
        """World vertices of the needle (tip first), computed once per pose."""
        return self._at_pose()[0]

    def tip_tangent(self) -> NDArray[np.float64]:
        """Unit direction the needle's tip points (world), computed once per pose."""
        return self._at_pose()[1]

    def _at_pose(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(vertices, tip tangent) of the current needle pose, read-only, recomputed when it changes
        (every FEM step needs both: the tangent goes into its snapshot)."""
        if self._pose_seen is not self.needle_pose:
            vertices = self.needle.world_vertices(self.needle_pose)
            tangent = self.needle.tip_tangent(self.needle_pose)
            vertices.flags.writeable = tangent.flags.writeable = False
            self._pose_seen, self._pose_geometry = self.needle_pose, (vertices, tangent)
        return self._pose_geometry

    def _track_tip(self, time: float) -> None:
        x, y, z = tip = tuple(self.needle_vertices()[0].tolist())  # plain floats: every FEM step
        if self._previous_tip is not None and time > self._previous_time:
            px, py, pz = self._previous_tip
            dt = time - self._previous_time
            vx, vy, vz = (x - px) / dt, (y - py) / dt, (z - pz) / dt
            self._tip_velocity = (vx, vy, vz)
            self.tip_speed = math.sqrt(vx * vx + vy * vy + vz * vz)
        self._previous_tip, self._previous_time = tip, time

    @property
    def tip_velocity(self) -> NDArray[np.float64]:
        """The tip's velocity (m/s, world) between the last two FEM steps."""
        return np.array(self._tip_velocity)

    # -- FEM rate -------------------------------------------------------------------------
    def fem_step(self, time: float) -> FemStep:
        """Local CD against the nominated triangle(s), forces, and the piercing decision."""
        previous_time, self._fem_time = self._fem_time, time
        self.kernel_loads = None  # (M, F): this step's reactions as M F, when its force kernels gave them
        vertices = self.needle_vertices()
        before, self._swept_from = self._swept_from, vertices
        met: list[NeedleEvent] = []
        if self.state in ("free", "contact"):
            met = self._meet(previous_time, time, before, vertices)
        if self.state == "free" or not self.contacts:
            self.last_contact = None
            self.local_stress = self.stretch = self.wound_edge_stress = math.nan
            self._check_stress(time, None)
            return FemStep.untouched(met)
        if not self.grasped and self.state != "contact":
            vertices = self._settle_released(vertices, time)
            self._swept_from = vertices
        if self.state == "contact":
            step = self._contact_step(time, vertices)
        else:
            step = self._pierced_step(vertices)
        step.events[:0] = met
        if self.state == "free":  # the tip was withdrawn this step
            self.local_stress = self.stretch = self.wound_edge_stress = math.nan
        elif len(step.contact_nodes) == 0:  # in the wall's state but no longer held (being pulled clear)
            self.local_stress, self.stretch, self.wound_edge_stress = 0.0, 1.0, math.nan
        self._check_stress(time, step)
        return step

    def _check_stress(self, time: float, step: FemStep | None) -> None:
        """An ``overstress`` event when the local stress first rises past the damage threshold, an
        ``edge_overstress`` event when the wound edge's does past its own (added to ``step``)."""
        forces = self.forces
        checks = (
            ("overstress", "local stress", self.local_stress, forces.damage_stress, "_overstressed"),
            (
                "edge_overstress",
                "wound-edge stress",
                self.wound_edge_stress,
                forces.edge_damage_stress,
                "_edge_overstressed",
            ),
        )
        for kind, what, stress, limit, flag in checks:
            over = limit is not None and stress >= limit  # nan compares False: below
            if over and not getattr(self, flag) and step is not None:
                contact = self.contacts[0] if self.contacts else None
                step.events.append(
                    NeedleEvent(
                        kind,
                        time,
                        -1 if contact is None else contact.triangle,
                        (math.nan,) * 3 if contact is None else tuple(contact.barycentric),
                        tip_speed=self.tip_speed,
                        detail=f"{what} {stress / 1e3:.0f} kPa over {limit / 1e3:.0f} kPa",
                    )
                )
            setattr(self, flag, over)

    def _let_go(self, time: float, kind: str, contact: TriangleContact, detail: str) -> NeedleEvent:
        """Back to the free state, and the event saying where the tissue let go of the needle."""
        self.state, self.contacts, self._handle, self._load = "free", [], None, None
        return NeedleEvent(
            kind, time, contact.triangle, tuple(contact.barycentric), tip_speed=self.tip_speed, detail=detail
        )

    def _meet(
        self, previous_time: float, time: float, before: NDArray | None, after: NDArray
    ) -> list[NeedleEvent]:
        """Continuous collision detection at the FEM rate (:func:`sim.needle.sweep.touches`): the
        needle's swept path since the last step against the surface. Its first crossing into the
        tissue starts a contact where and when it happened: at the tip (which may pierce) or, if the
        body met the wall first, at that point of the body (pushed back, it cannot pierce). In contact,
        a crossing well away from every current contact (beyond its triangle's size plus 2 mm: nearer,
        the needle's body dips below the undeformed surface as the tip presses in) is another contact,
        up to :attr:`max_surface_contacts`."""
        events = []
        # points within reach of a current contact or a hole the needle made
        known = KnownBalls.of(
            [c.point for c in self.contacts] + self._holes,
            [self._triangle_reach(c) + NEAR_CONTACT for c in self.contacts] + [HOLE_REACH] * len(self._holes),
        )
        for touch in touches(self.collision, before, after, known):
            event = self._touched(touch, previous_time, time, before, after)
            if event is not None:
                events.append(event)
            if self.state not in ("free", "contact"):
                break
        return events

    def _touched(
        self, touch: Touch, previous_time: float, time: float, before: NDArray | None, after: NDArray
    ) -> NeedleEvent | None:
        """A contact for ``touch`` (and its ``contact_start``), unless it is the needle following its
        tip through its holes, near a current contact, beyond the contacts modelled at once, or only
        on the surface by the end of the step."""
        if not touch.at_tip and self._near_holes(touch.point)[0]:
            return None  # the rest of the needle following its tip through the holes it made
        if self.state == "contact" and (
            len(self.contacts) >= self.max_surface_contacts
            or self._near_contacts(touch.point, NEAR_CONTACT)[0]
        ):
            return None
        triangle = touch.triangle
        contact = TriangleContact(
            triangle,
            self.collision.triangles[triangle].copy(),
            touch.barycentric,
            touch.point.copy(),
            self.collision.normals[triangle].copy(),
        )
        material = (0, 1.0) if touch.at_tip else (touch.segment, touch.along)
        if contact.penetration(self._material_point(after, *material)) <= 0.0:
            return None  # it ends this step on the surface, not yet in it
        if self.state == "free":
            self.contacts, self._touches, self.state = [], [], "contact"
            self._holes = []
            self._torn = set()
            self.forces = self.forces_at(triangle)
        self.contacts.append(contact)
        self._touches.append(material)
        self._handle = self._load = None
        if touch.at_tip:
            angle, detail = entry_angle_deg(self.tip_tangent(), contact.normal), ""
        else:
            where = (np.array([touch.segment]), np.array([1.0 - touch.along]))
            from_tip = float(self.needle.arc_position(*where)[0])
            angle = math.nan
            detail = f"needle body, {from_tip * 1e3:.1f} mm from the tip: pushed back, cannot pierce there"
        if len(self.contacts) > 1:
            detail = f"{detail}; {len(self.contacts)} contacts at once".lstrip("; ")
        when = previous_time + touch.fraction * (time - previous_time) if before is not None else time
        return NeedleEvent(
            "contact_start", when, triangle, tuple(touch.barycentric.tolist()), angle, self.tip_speed, detail
        )

    @staticmethod
    def _material_point(vertices: NDArray, segment: int, along: float) -> NDArray:
        """The point ``along`` (1 = the tip end) needle segment ``segment`` (from vertex k+1 to k)."""
        if segment == 0 and along == 1.0:
            return vertices[0]
        return vertices[segment + 1] + along * (vertices[segment] - vertices[segment + 1])

    def _contact_step(self, time: float, vertices: NDArray) -> FemStep:
        """The needle pressing on the surface at one or more contacts: those whose point of the needle
        has come back above its triangle's plane let go (``contact_end`` when the last does); the tip's
        contact pierces at an acceptable angle and normal force."""
        points = [self._material_point(vertices, *touch) for touch in self._touches]
        pairs = zip(self.contacts, points, strict=True)
        held = [k for k, (contact, point) in enumerate(pairs) if contact.penetration(point) > 0.0]
        if not held:
            what = "tip" if (0, 1.0) in self._touches else "needle body"
            event = self._let_go(time, "contact_end", self.contacts[0], f"{what} withdrawn above the surface")
            return FemStep.untouched([event])
        if len(held) < len(self.contacts):
            self.contacts = [self.contacts[k] for k in held]
            self._touches = [self._touches[k] for k in held]
            points = [points[k] for k in held]
            self._load = self._handle = None  # a smaller set of kernels
        displacements = np.array([p - c.point for c, p in zip(self.contacts, points, strict=True)])
        events = []
        if self.forces.load == "kernel":
            key = tuple(("surface", rank) for rank in range(len(self.contacts)))
            normals = np.array([c.normal for c in self.contacts])
            nodes, reactions, torn = self._kernel_reactions(
                key, displacements, np.zeros_like(displacements), normals
            )
            events += self._tear_events(time, torn)
        else:  # the paper's rule: one contact, its triangle's nodes driven by their barycentric weights
            contact, displacement = self.contacts[0], displacements[0]
            nodes = contact.nodes
            intended = contact.barycentric[:, None] * displacement
            reactions = self._reactions(contact.nodes, intended, displacement)
            self._nodal_stress(nodes, reactions, [contact.point], displacement[None, :])
        force = -reactions.sum(axis=0)
        if (0, 1.0) not in self._touches:
            return FemStep(force, nodes, reactions, events)
        contact = self.contacts[self._touches.index((0, 1.0))]
        normal_force = float(force @ contact.normal)  # the tissue pushes the needle back out
        threshold = self.forces.puncture_force
        punctured = (
            normal_force >= threshold
            if threshold is not None
            else normal_force / self.needle.wire_area >= self.rules.puncture_stress
        )
        angle = entry_angle_deg(self.tip_tangent(), contact.normal) if punctured else math.inf
        if angle <= self.rules.max_entry_angle_deg:
            self.state = "pierced"
            self.contacts, self._touches = [contact], []
            self._handle = None
            self._load = None
            self._start_passage(contact)
            events.append(
                NeedleEvent(
                    "pierce",
                    time,
                    contact.triangle,
                    tuple(contact.barycentric),
                    angle,
                    self.tip_speed,
                    f"normal force {1e3 * normal_force:.0f} mN",
                )
            )
        return FemStep(force, nodes, reactions, events)

    def _start_passage(self, contact: TriangleContact) -> None:
        """At the pierce: the wall's length along the tip's direction from the entry point (to the
        far surface the emergence ramp ends on), and no wall cut yet."""
        self._deepest = 0.0
        self._torn = set()
        direction = self.tip_tangent()
        self._wall_path = self.collision.distance_through(contact.point, direction, contact.triangle)

    def _pierced_step(self, vertices: NDArray) -> FemStep:
        tangent = self.tip_tangent()
        crossings = []
        for rank, contact in enumerate(self.contacts):
            point = self._needle_point_at_plane(vertices, contact)
            if point is None or not self._holds(contact, point):
                continue  # the needle has left this crossing (the wall lets go of it)
            offset = point - contact.point
            sideways = offset - offset.dot(tangent) * tangent  # the needle slides freely along itself
            crossings.append((rank, sideways))
        if not crossings:
            return FemStep.untouched()
        if self.forces.load == "kernel":
            axial = self._axial_forces(vertices, tangent, len(crossings))
            key = tuple(("wall", rank) for rank, _ in crossings)
            sideways = np.array([offset for _, offset in crossings])
            all_nodes, reactions, torn = self._kernel_reactions(key, sideways, axial)
            return FemStep(
                -reactions.sum(axis=0), all_nodes, reactions, self._tear_events(self._fem_time, torn)
            )
        nodes = [self.contacts[rank].nodes for rank, _ in crossings]
        # the paper's rule: each crossed triangle's nodes driven by their barycentric weights (np.outer,
        # without its wrapper)
        intended = [self.contacts[rank].barycentric[:, None] * offset for rank, offset in crossings]
        if len(nodes) == 1:
            all_nodes, merged = nodes[0], intended[0]
        else:  # entry and exit triangles may share nodes: add their intended displacements
            all_nodes = np.unique(np.concatenate(nodes))
            merged = np.zeros((len(all_nodes), 3))
            np.add.at(merged, np.searchsorted(all_nodes, np.concatenate(nodes)), np.concatenate(intended))
        reactions = self._reactions(all_nodes, merged, merged.sum(axis=0))
        points = [c.point for c in self.contacts]
        self._nodal_stress(all_nodes, reactions, points, np.array([o for _, o in crossings]))
        return FemStep(-reactions.sum(axis=0), all_nodes, reactions)


__all__ = ["EVENT_KINDS", "FemStep", "InteractionError", "NeedleEvent", "NeedleInteraction"]
__all__ += ["PiercingRules", "entry_angle_deg"]
