"""How far a cramped approach lets the wrist turn the needle back: the wrist's stop.

A curved needle is driven by turning the holder about its own shaft (the needle's circle axis,
:mod:`sim.needle.geometry`); the tip's direction swings with that turn. At the start of a drive
the wrist is fully pronated, and where the wound is deep or the edge lies under its neighbour
(the inside of a wound's edge: PAPER.md section 2, "the subordinate hand is used mainly to
facilitate this access, which has to be sufficient to allow perpendicular entry of a curved
needle") full pronation can leave the tip short of square to the resting wall. The surgeon's
answer is the other hand: everting the edge turns the wall to meet the needle.

:class:`WristStop` holds that limit as one world direction, ``tip_limit``: the furthest back
(against the drive) the held needle's tip can point, and the wrist's range forward of it. A held
needle whose tip points further back is turned forward about its own axis through its circle's
centre, the holder with it (the wrist cannot turn it further: a hand that turns the needle about
that centre, as a drive does, moves it no further), so the tip meets the wall where the stop lets
it, and the entry angle is measured against the wall where it is. The stop holds the grip that
drives the needle in, through the wall too (the drive turns forward, away from it, so a needle
held at the stop is never let go of with a jump); the re-grasp at the tip to pull the needle
through is a new grip with the wrist reset, which the stop lets be.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sim.geometry import circle_through
from sim.needle.events import NeedleEvent
from sim.needle.geometry import Needle, NeedleError, Pose, rotation_about

WRIST_RANGE_DEG = 160.0
"""The forearm's turn from full pronation to full supination, which drives a curved needle: about
80 deg each way in healthy adults (the AAOS's normal values), of which daily tasks use 100 deg
(Morrey et al. 1981, J Bone Joint Surg Am 63:872); more than a 3/8-circle needle's 135 deg."""
DEGENERATE_SHAFT = 0.3
"""Below this length of ``tip_limit``'s part across the shaft (a sine), the shaft points nearly
along the stop's direction: the stop cannot be met by turning about it and is not applied."""


@dataclass(frozen=True)
class WristStop:
    """The furthest back a held needle's tip can point: ``tip_limit`` (unit, world), and
    ``range_deg`` of the wrist's turn forward of it (see the module docstring)."""

    tip_limit: NDArray[np.float64]
    range_deg: float = WRIST_RANGE_DEG

    def __post_init__(self) -> None:
        limit = np.asarray(self.tip_limit, dtype=np.float64)
        norm = float(np.linalg.norm(limit)) if limit.shape == (3,) else math.nan
        if not (math.isfinite(norm) and norm > 0):
            raise NeedleError(f"a wrist stop's tip_limit must be a non-zero 3-vector; got {self.tip_limit!r}")
        if not 0 < self.range_deg < 360:
            raise NeedleError(f"a wrist stop's range_deg must be in (0, 360) deg; got {self.range_deg}")
        object.__setattr__(self, "tip_limit", limit / norm)

    @classmethod
    def short_of_square(cls, normal: ArrayLike, bite_direction: ArrayLike, short_deg: float) -> WristStop:
        """The stop of a bite whose wall faces ``normal`` (outward) and whose needle is driven towards
        ``bite_direction``: full pronation leaves the tip ``short_deg`` past square, tipped towards
        the bite (a wall turned that far away from the bite, by everting its edge, is met square)."""
        n = np.asarray(normal, dtype=np.float64)
        n = n / np.linalg.norm(n)
        s = np.asarray(bite_direction, dtype=np.float64)
        s = s - (s @ n) * n
        s = s / np.linalg.norm(s)
        short = math.radians(short_deg)
        return cls(math.cos(short) * -n + math.sin(short) * s)

    def turn_past(self, tip: NDArray[np.float64], shaft: NDArray[np.float64]) -> float:
        """How far (rad) the tip direction ``tip`` is turned forward (about the unit ``shaft``, the
        drive's sense) from the stop; nan when the shaft points along the stop's direction."""
        limit = self.tip_limit - float(self.tip_limit @ shaft) * shaft
        across = float(np.linalg.norm(limit))
        if across < DEGENERATE_SHAFT:
            return math.nan
        limit /= across
        return math.atan2(float(shaft @ np.cross(limit, tip)), float(limit @ tip))

    def correction(self, tip: NDArray[np.float64], shaft: NDArray[np.float64]) -> float:
        """The turn (rad, about ``shaft``) that brings ``tip`` inside the wrist's range: 0 inside it;
        forward to the stop from behind it, back to the range's end from past it (whichever end is
        nearer)."""
        past = self.turn_past(tip, shaft)
        if not math.isfinite(past) or -1e-12 <= past <= math.radians(self.range_deg) + 1e-12:  # rounding
            return 0.0
        behind = -past if past < 0 else 2 * math.pi - past  # forward turn to the stop
        beyond = (
            past - math.radians(self.range_deg)
            if past > 0
            else past + 2 * math.pi - math.radians(self.range_deg)
        )  # back turn to the range's end
        return behind if behind <= beyond else -beyond


class WristLimit:
    """A :class:`WristStop` on the hand holding ``needle``: :meth:`hold` gives the holder's pose as the
    wrist can take it and a ``wrist_stop`` event each time the stop starts holding the wrist by at
    least :data:`NOTICED_DEG` (again once the tip has come :data:`REARM_DEG` forward of it). It holds
    the grip that drives the needle in; :meth:`regrip` with the needle in the wall (the re-grasp at
    the tip to pull it through) resets the wrist, and the stop lets that grip be."""

    def __init__(self, stop: WristStop, needle: Needle) -> None:
        self.stop, self.needle = stop, needle
        self.holding = False
        self.released = False  # re-gripped in the wall: the stop no longer applies
        self._axis = np.array([0.0, 0.0, 1.0])  # the needle's circle axis, its own frame
        vertices = needle.vertices
        circle = circle_through(vertices[0], vertices[len(vertices) // 2], vertices[-1])
        self._centre = np.zeros(3) if circle is None else circle[0]  # its own frame; straight: the jaws

    def regrip(self, in_wall: bool) -> None:
        """The needle re-grasped; ``in_wall``: with the needle through the wall (the stop lets go)."""
        self.released = self.released or in_wall

    def hold(self, time: float, holder: Pose, grasp: Pose) -> tuple[Pose, list[NeedleEvent]]:
        if self.released:
            return holder, []
        rotation = holder.rotation.dot(grasp.rotation)
        shaft, tip = rotation.dot(self._axis), rotation.dot(self.needle.tip_direction)
        turn = self.stop.correction(tip, shaft)
        if turn == 0.0:
            if self.holding and not self.stop.turn_past(tip, shaft) < math.radians(REARM_DEG):
                self.holding = False
            return holder, []
        events = []
        if not self.holding and turn >= math.radians(NOTICED_DEG):
            self.holding = True
            words = f"the tip held {math.degrees(turn):.1f} deg short of where the hand turned it"
            events.append(NeedleEvent("wrist_stop", time, detail=words))
        # turned about the needle's own centre: the needle stays on its circle where the wrist's last
        # possible turn left it (a hand turning it about that centre, as a drive does, then moves it
        # no further), the holder with it
        centre = holder.position + holder.rotation.dot(grasp.position + grasp.rotation.dot(self._centre))
        turned = rotation_about(shaft, turn)
        position = centre + turned.dot(holder.position - centre)
        return Pose.unchecked(position, turned.dot(holder.rotation)), events


NOTICED_DEG = 0.1
"""A stop holding the wrist by less than this (deg) is applied but not reported."""
REARM_DEG = 1.0
"""After a ``wrist_stop`` event the next needs the tip this far (deg) forward of the stop first: a
hand trembling at the stop makes one event, not one per step."""

__all__ = ["NOTICED_DEG", "REARM_DEG", "WRIST_RANGE_DEG", "WristLimit", "WristStop"]
