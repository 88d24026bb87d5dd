"""The graphics-rate half of the needle-tissue interaction: global collision detection of the whole
needle against the collision mesh, the first crossing at the tip promoted to a contact, the exit
through the far wall, the end of the passage, and implausible hits (reported when they start).

A mixin of :class:`sim.needle.interaction.NeedleInteraction`, which holds the state these methods read
and change (``state``, ``contacts``, the collision mesh) and the FEM-rate half.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from sim.collision.mesh import TriangleContact, segment_ends
from sim.collision.segments import plane_crossing
from sim.needle.events import NeedleEvent, entry_angle_deg

HOLE_REACH = 1.5e-3
"""After a pull-through, the needle's body crossing the surface this close (m) to the passage's entry
or exit point is the body following its tip through the wall, not a new contact (until a contact
starts)."""
NEAR_CONTACT = 2e-3
"""Crossings within a contact triangle's size plus this (m) of a contact are that contact: near it the
needle's body dips below the undeformed surface as the tip presses in (the collision mesh ignores
the needle's own deformation of the wall)."""
TORN_HOLE = 2e-3
"""How much further (m) a torn entry holds the needle: levered through the wall it has cut a slit, and
where its body crosses the (curved) surface may lie that far beyond where the wall holds it."""


class GraphicsRateTracking:
    """Global CD and what follows from it (see the module docstring)."""

    max_surface_contacts = 4
    """Most points of one needle pressing on the surface at once (the tip and three of the body)."""

    def graphics_step(self, time: float) -> list[NeedleEvent]:
        """Global CD of the whole needle; promotes, exits, completes passages, flags implausible hits."""
        vertices = self.needle_vertices()
        return self.apply_global(time, vertices, self.collision.query(vertices))

    def apply_global(self, time: float, vertices: NDArray, hits) -> list[NeedleEvent]:
        """Act on global-CD hits computed elsewhere (the graphics thread) for these needle vertices."""
        events: list[NeedleEvent] = []
        if self.state == "free":
            events += self._promote(time, vertices, hits)
        elif self.state == "contact":
            events += self._check_contact(time, vertices, hits)
        elif self.state in ("pierced", "exited"):
            events += self._track_passage(time, vertices, hits)
        return self._new_implausible_only(events)

    def _new_implausible_only(self, events: list[NeedleEvent]) -> list[NeedleEvent]:
        """Report an implausible condition when it starts, not on every frame it lasts."""
        current = {(e.detail, e.triangle) for e in events if e.kind == "implausible_hit"}
        fresh = [
            e
            for e in events
            if e.kind != "implausible_hit" or (e.detail, e.triangle) not in self._implausible_active
        ]
        self._implausible_active = current
        return fresh

    def _promote(self, time: float, vertices: NDArray, hits) -> list[NeedleEvent]:
        if len(hits) == 0:
            return []
        if self._holes:  # the needle's body still following its tip out through the holes it made
            away = np.flatnonzero(~self._near_holes(hits.points(*segment_ends(vertices))))
            if not away.size:
                return []
            hits = hits.take(away)
        if not hits.entering[0] and not self._at_held_edge[hits.triangle[0]]:
            # The part of the needle nearest the tip crosses a surface from inside the tissue
            # without having pierced it: entry through the wrong face (unless beside the model's
            # held edge, which the needle's body can pass round where the real wall goes on).
            return [
                self._event("implausible_hit", time, hits, 0, "needle inside the tissue without piercing")
            ]
        return []  # a crossing into the tissue: the FEM rate's continuous test has started its contact

    def _check_contact(self, time: float, vertices: NDArray, hits) -> list[NeedleEvent]:
        """While in contact with as many points as are modelled at once, flag crossings well away from
        every contact point (below that, the FEM rate's continuous test makes further touches contacts).

        Near the contact the needle's body dips below the undeformed surface as the
        tip presses in (the collision mesh ignores the needle's own deformation), so
        only crossings farther than the contact triangle's size plus 2 mm count.
        """
        if len(self.contacts) < self.max_surface_contacts:
            return []  # room for more contacts: the FEM rate's continuous test makes further touches them
        points = hits.points(*segment_ends(vertices))
        away = np.flatnonzero(~self._near_contacts(points, NEAR_CONTACT))
        return [
            self._event("implausible_hit", time, hits, int(k), "needle touches the tissue elsewhere")
            for k in away[:1]
        ]

    def _track_passage(self, time: float, vertices: NDArray, hits) -> list[NeedleEvent]:
        entry = self.contacts[0]
        points = hits.points(*segment_ends(vertices)) if len(hits) else np.zeros((0, 3))
        # the crossing back through the entry surface: the entry triangle, or (on a fine mesh, as the
        # needle's body sweeps a little sideways) an entering crossing the wall still holds
        near_entry = hits.entering & self._within_reach(entry, points, self._hold_margin(entry))
        through_entry = np.flatnonzero((hits.triangle == entry.triangle) | near_entry)
        still_held = [
            c
            for c in self.contacts
            if np.any(hits.triangle == c.triangle) or self._crosses_plane_near(vertices, c)
        ]
        if not still_held:
            self._holes = [c.point.copy() for c in self.contacts]  # the needle's tail follows through them
            return [self._let_go(time, "pull_through", entry, "needle pulled clear of the wall")]
        events = []
        entry_rank = int(through_entry[0]) if through_entry.size else len(hits)
        # the crossings nearer the tip than the entry, from the entry towards the tip, alternate out of a
        # wall and into the next (a bite through both edges of a wound: out of one edge's cut face,
        # into the other's, out through its surface); the first out of turn is implausible
        chain: list[int] = []
        for k in range(entry_rank - 1, -1, -1):
            if bool(hits.entering[k]) != (len(chain) % 2 == 1):
                break
            chain.append(k)
        held = len(self.contacts) - 1  # crossings beyond the entry the wall already holds
        for position, k in enumerate(chain[held:], start=held):
            self.contacts.append(TriangleContact.from_hit(self.collision, hits, k, points[k]))
            self._handle = None
            self._load = None
            if position == 0 and self.state == "pierced":
                self.state = "exited"
                angle = entry_angle_deg(-self.tip_tangent(), self.collision.normals[hits.triangle[k]])
                events.append(self._event("exit", time, hits, k, "", angle))
        for k in range(entry_rank - 1 - len(chain), -1, -1):
            if hits.entering[k]:
                events.append(self._event("implausible_hit", time, hits, k, "needle enters a second wall"))
        return events

    def _crosses_plane_near(self, vertices: NDArray, contact: TriangleContact) -> bool:
        """Whether the needle still crosses the entry plane close to the entry point (see :meth:`_holds`)."""
        point = self._needle_point_at_plane(vertices, contact)
        return point is not None and self._holds(contact, point)

    def _holds(self, contact: TriangleContact, point: NDArray) -> bool:
        """Whether the wall still holds the needle crossing its plane at ``point``: within the
        nominated triangle's size plus 1 mm of the contact point, so a needle held sideways in the
        wound still counts as passing through it, and one whose other end crosses the plane far
        away (as it is pulled clear) does not."""
        reach = self._triangle_reach(contact) + self._hold_margin(contact)
        offset = point - contact.point
        return float(offset.dot(offset)) <= reach * reach

    def _hold_margin(self, contact: TriangleContact) -> float:
        """How far (m) beyond its triangle's size the wall holds a needle crossing its plane (see
        :meth:`_holds`)."""
        if self.contacts and contact is self.contacts[0] and 0 in self._torn:
            return 1e-3 + TORN_HOLE  # a torn entry is a slit the needle was levered along
        return 1e-3

    def _triangle_reach(self, contact: TriangleContact) -> float:
        """The contact triangle's size seen from the contact point (m): its farthest corner's distance,
        remembered while the contact and the collision mesh's corners stay the same objects (each
        FEM step asks it of every crossing)."""
        corners = self.collision.corners
        for known, known_corners, reach in self._reaches:
            if known is contact and known_corners is corners:
                return reach
        reach = float(np.linalg.norm(corners[contact.triangle] - contact.point, axis=1).max())
        self._reaches = [*self._reaches[-3:], (contact, corners, reach)]
        return reach

    def _within_reach(self, contact: TriangleContact, points: NDArray, margin: float) -> NDArray[np.bool_]:
        """Whether each of ``points`` ((N, 3) or one) lies within the contact triangle's size plus
        ``margin`` (m) of the contact point."""
        reach = self._triangle_reach(contact) + margin
        offsets = np.atleast_2d(points) - contact.point
        return np.einsum("ij,ij->i", offsets, offsets) <= reach * reach

    def _near_contacts(self, points: NDArray, margin: float) -> NDArray[np.bool_]:
        """Whether each of ``points`` ((N, 3) or one) is within reach (``margin``) of a current contact."""
        near = np.zeros(len(np.atleast_2d(points)), dtype=bool)
        for contact in self.contacts:
            near |= self._within_reach(contact, points, margin)
        return near

    def _near_holes(self, points: NDArray) -> NDArray[np.bool_]:
        """Whether each of ``points`` ((N, 3) or one) lies within :data:`HOLE_REACH` of a hole of the
        last passage pulled through (the needle's body following its tip out through them)."""
        offsets = np.atleast_2d(points)[:, None, :] - np.asarray(self._holes).reshape(1, -1, 3)
        return (np.einsum("ijk,ijk->ij", offsets, offsets) <= HOLE_REACH * HOLE_REACH).any(axis=1)

    @staticmethod
    def _needle_point_at_plane(vertices: NDArray, contact: TriangleContact) -> NDArray | None:
        """Where the needle crosses the contact's plane, the crossing nearest the contact point (one
        compiled pass: read twice each FEM step through the wall)."""
        return plane_crossing(vertices, contact.normal, contact.point)

    def _event(
        self, kind: str, time: float, hits, k: int, detail: str, angle: float = math.nan
    ) -> NeedleEvent:
        return NeedleEvent(
            kind,
            time,
            int(hits.triangle[k]),
            tuple(float(x) for x in hits.barycentric[k]),
            angle,
            self.tip_speed,
            detail,
        )
