"""The scripted suturing hand: one pass of a curved needle through the wall (approach, a
perpendicular entry, the wrist's rotation along the needle's curve, release, re-grasp and pull-through),
with the imperfections a trainee's hand adds (entry angle, speed, hesitations, tremor, levering), and
a row of passes; each a trajectory for :class:`sim.devices.scripted.ScriptedDevice`.
"""

from __future__ import annotations

import bisect
import functools
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sim.collision.mesh import segment_ends
from sim.devices.base import DeviceError, Trajectory
from sim.geometry import circle_through
from sim.needle import Needle, Pose, TurnAbout, rotation_about


@dataclass(frozen=True)
class SuturingPassParameters:
    """Skill parameters of a scripted suturing pass with a curved needle.

    entry_angle_deg: tilt of the needle tip from the inward normal at entry (0 = perpendicular).
    insertion_speed: needle-tip speed along its arc (m/s).
    wrist_rotation: 1 = the wrist turns the needle about its own centre (it follows its
        curve); 0 = the hand pushes it straight along the entry direction (levering).
    insertion_arc_deg: how far the needle is turned before it is released (the tip should
        then be through the wall).
    hesitations: number of pauses during insertion, each ``hesitation_time`` s long.
    tremor_amplitude (m) and tremor_frequency (Hz): hand tremor added to the holder.
    approach_time (s), approach_distance (m): the needle descends onto the entry point.
    regrab_time (s): jaws travel from the grip to the needle's tip and close on it.
    pull_arc_deg: the needle is then turned on along its own curve, so its body follows the
        tip's path through the wall, until this much further.
    pull_speed: the tip's speed along its arc while pulling through (m/s); None: the insertion
        speed.
    entry_offset (m): where the hand actually enters, off the intended entry point along the
        bite direction (positive: towards the exit, i.e. a smaller bite from a wound edge there);
        lateral_offset (m): off it across the bite direction.
    seed: for the tremor's phases (a pass is reproducible).
    """

    entry_angle_deg: float = 0.0
    insertion_speed: float = 0.004
    wrist_rotation: float = 1.0
    insertion_arc_deg: float = 70.0
    hesitations: int = 0
    hesitation_time: float = 0.4
    tremor_amplitude: float = 0.0
    tremor_frequency: float = 9.0
    approach_time: float = 0.8
    approach_distance: float = 0.004
    regrab_time: float = 0.6
    pull_arc_deg: float = 170.0
    pull_speed: float | None = None
    entry_offset: float = 0.0
    lateral_offset: float = 0.0
    seed: int = 0


class SuturingPass:
    """A whole stitch: approach, insertion by wrist rotation, release, re-grab at the tip, pull-through.

    entry: entry point on the tissue surface (m); normal: outward surface normal there;
    bite_direction: along the surface towards the exit; approach: the direction the hand
    descends from onto the entry point (default: the normal). The needle's circle lies in
    the plane of the normal and the bite direction; its tip reaches the entry point
    at the end of the approach with the parameters' entry angle (tilted away from
    the bite). ``pose_and_grip(t)`` is a trajectory for :class:`ScriptedDevice`.
    """

    def __init__(
        self,
        needle: Needle,
        entry: ArrayLike,
        normal: ArrayLike,
        bite_direction: ArrayLike,
        parameters: SuturingPassParameters | None = None,
        approach: ArrayLike | None = None,
    ) -> None:
        self.needle = needle
        self.p = parameters or SuturingPassParameters()
        n = _unit(normal)
        self.approach = n if approach is None else _unit(approach)
        """The direction (from the entry point) the hand descends along: the normal, or where a
        restricted access lets it come from; it must come from outside the wall."""
        if not self.approach @ n > 0.05:
            raise DeviceError("a suturing pass must approach from outside the wall (approach . normal > 0)")
        s = np.asarray(bite_direction, dtype=np.float64)
        s = _unit(s - (s @ n) * n)
        tilt = math.radians(self.p.entry_angle_deg)
        tangent = math.cos(tilt) * -n - math.sin(tilt) * s  # tip direction at entry
        to_centre = _unit(s - (s @ tangent) * tangent)
        centre_local, full, self.radius = _needle_circle(needle)
        tip_local = needle.vertices[0]
        local = np.column_stack(
            [
                (centre_local - tip_local) / self.radius,
                [-math.sin(full), math.cos(full), 0.0],
                [0.0, 0.0, 1.0],
            ]
        )
        self.axis = -np.cross(to_centre, tangent)  # turning about it drives the tip along its curve
        world = np.column_stack([to_centre, tangent, self.axis])
        self._rest = world @ local.T
        self._centre_local = centre_local
        offset = self.p.entry_offset * s + self.p.lateral_offset * np.cross(n, s)
        self.entry = np.asarray(entry, dtype=np.float64) + offset
        self.centre = self.entry + self.radius * to_centre
        at_entry = Pose.unchecked(self.centre - self._rest @ centre_local, self._rest)
        self._turn = TurnAbout(self.axis, self.centre, at_entry)  # the holder, turned from entry
        self.normal, self.tangent = n, tangent
        self._tremor_phase = np.random.default_rng(self.p.seed).uniform(0, 2 * math.pi, size=3)
        # rad/s per axis; (2 pi) * f as the expression 2 * math.pi * f * t would group it
        self._tremor_omega = 2 * math.pi * (self.p.tremor_frequency * np.array([1.0, 1.13, 0.87]))
        self._omega = self.p.insertion_speed / self.radius
        self._insert_time = (
            math.radians(self.p.insertion_arc_deg) / self._omega + self.p.hesitations * self.p.hesitation_time
        )
        pull_speed = self.p.insertion_speed if self.p.pull_speed is None else self.p.pull_speed
        if not (math.isfinite(pull_speed) and pull_speed > 0):
            raise DeviceError(f"a suturing pass's pull_speed must be a positive speed (m/s): {pull_speed}")
        self._pull_omega = pull_speed / self.radius
        self._pull_time = math.radians(self.p.pull_arc_deg) / self._pull_omega
        self.duration = self.p.approach_time + self._insert_time + self.p.regrab_time + self._pull_time
        self._sees: Callable[[], Pose] | None = None
        self._correction: Pose | None = None  # where the needle lay at the re-grasp against the plan

    def see_needle(self, needle_pose: Callable[[], Pose] | None) -> None:
        """Let the hand see the needle (``needle_pose()``: its world pose; holder frame = needle frame
        while held). A needle released in the wall settles where the wall holds it, so a hand that
        sees goes for the needle's tip where it lies and pulls it on along the needle's own curve
        from there; without it (``None``) the hand follows its plan, the needle where it let go."""
        self._sees, self._correction = needle_pose, None

    def _where_the_needle_lies(self) -> Pose | None:
        """The rigid move from the planned released needle to the one the hand sees (None: blind)."""
        if self._correction is not None:
            return self._correction
        if self._sees is None:
            return None
        released, _ = self._release
        return self._sees().compose(released.inverse())

    @property
    def phases(self) -> dict[str, tuple[float, float]]:
        """Start and end (s) of the approach, insertion, regrab and pull phases."""
        return dict(self._phases)

    @functools.cached_property
    def _phases(self) -> dict[str, tuple[float, float]]:
        a = self.p.approach_time
        b = a + self._insert_time
        c = b + self.p.regrab_time
        return {"approach": (0.0, a), "insertion": (a, b), "regrab": (b, c), "pull": (c, self.duration)}

    def turned(self, angle: float) -> Pose:
        """Holder (= needle) pose with the needle turned by ``angle`` (rad) about its centre from entry."""
        return self._turn.pose(angle)

    def _insertion_angle(self, t: float) -> float:
        """Angle turned after ``t`` s of insertion, with pauses spread evenly through it."""
        moving = t
        if self.p.hesitations:
            span = self._insert_time / (self.p.hesitations + 1)
            for k in range(1, self.p.hesitations + 1):
                start = k * span - self.p.hesitation_time / 2
                moving -= min(max(t - start, 0.0), self.p.hesitation_time)
        return min(self._omega * max(moving, 0.0), math.radians(self.p.insertion_arc_deg))

    def _tremor(self, t: float) -> NDArray[np.float64]:
        if self.p.tremor_amplitude == 0:
            return np.zeros(3)
        return self.p.tremor_amplitude * np.sin(self._tremor_omega * t + self._tremor_phase)

    def pose_and_grip(self, t: float) -> tuple[Pose, bool]:
        # Every haptic tick: terms that are exactly zero (no push when the wrist does all the
        # turning, no tremor) are not added, which leaves the same floats.
        phases = self._phases
        if t < phases["insertion"][0]:
            pose = self._at_entry
            lift = (1.0 - max(t, 0.0) / self.p.approach_time) * self.p.approach_distance
            pose, grip = Pose.unchecked(pose.position + lift * self.approach, pose.rotation), True
        elif t < phases["regrab"][0]:
            angle = self._insertion_angle(t - phases["insertion"][0])
            pose, grip = self.turned(self.p.wrist_rotation * angle), True
            if self.p.wrist_rotation != 1.0:
                push = (1.0 - self.p.wrist_rotation) * self.radius * angle * self.tangent
                pose = Pose.unchecked(pose.position + push, pose.rotation)
        else:
            pose, grip = self._regrab_and_pull(t, *phases["regrab"])
        if self.p.tremor_amplitude == 0:
            return pose, grip
        return Pose.unchecked(pose.position + self._tremor(t), pose.rotation), grip

    @functools.cached_property
    def _at_entry(self) -> Pose:
        """The holder pose that puts the tip on the entry point (the approach descends onto it)."""
        return self.turned(0.0)

    @property
    def final_needle_pose(self) -> Pose:
        """Where the needle is at the end of the pull (the holder's frame at the original grip)."""
        released, _ = self._release
        centre = self._released_centre
        turn = rotation_about(self.axis, self._pull_omega * (self.duration - self.phases["pull"][0]))
        planned = Pose.unchecked(centre + turn @ (released.position - centre), turn @ released.rotation)
        return planned if self._correction is None else self._correction.compose(planned)

    @functools.cached_property
    def _release(self) -> tuple[Pose, NDArray[np.float64]]:
        """Holder pose when the needle is released, and where its tip is then."""
        inserted = math.radians(self.p.insertion_arc_deg)
        released = self.turned(self.p.wrist_rotation * inserted)
        push = (1 - self.p.wrist_rotation) * self.radius * inserted * self.tangent
        released = Pose.unchecked(released.position + push, released.rotation)
        return released, self.needle.world_vertices(released)[0]

    def _regrab_and_pull(self, t: float, start: float, stop: float) -> tuple[Pose, bool]:
        released, tip = self._release
        seen = self._where_the_needle_lies()
        if t < stop:  # jaws open, travel from the grip point to the needle's tip, close on arrival
            w = (t - start) / (stop - start)
            closing = w >= 0.98
            if seen is None:
                return Pose.unchecked((1 - w) * released.position + w * tip, released.rotation), closing
            if closing and self._sees is not None:
                self._correction = seen  # the jaws close on the needle where it lies now
            target = seen.compose(Pose.unchecked(tip, released.rotation))
            return blend_poses(released, target, w), closing
        pose = self._pull.pose(self._pull_omega * (t - stop))
        return pose if seen is None else seen.compose(pose), True

    @functools.cached_property
    def _released_centre(self) -> NDArray[np.float64]:
        """The centre of the needle's circle where it was released (moved by a pushing hand's push)."""
        inserted = math.radians(self.p.insertion_arc_deg)
        return self.centre + (1 - self.p.wrist_rotation) * self.radius * inserted * self.tangent

    @functools.cached_property
    def _pull(self) -> TurnAbout:
        """The holder, closed on the released needle's tip, turned on along the needle's own curve."""
        released, tip = self._release
        return TurnAbout(self.axis, self._released_centre, Pose.unchecked(tip, released.rotation))


def _unit(v: ArrayLike) -> NDArray[np.float64]:
    v = np.asarray(v, dtype=np.float64)
    norm = np.linalg.norm(v)
    if not norm > 0:
        raise DeviceError("direction vectors of a suturing pass must be non-zero")
    return v / norm


def _needle_circle(needle: Needle) -> tuple[NDArray[np.float64], float, float]:
    """(centre in the holder frame, arc angle swage -> tip (rad), radius) of a curved needle."""
    a, b, c = needle.vertices[0], needle.vertices[len(needle.vertices) // 2], needle.vertices[-1]
    circle = circle_through(a, b, c)
    if circle is None:
        raise DeviceError("a suturing pass needs a curved needle")
    centre, radius = circle
    tip, swage = a - centre, c - centre
    angle = (math.atan2(tip[1], tip[0]) - math.atan2(swage[1], swage[0])) % (2 * math.pi)
    return centre, angle, radius


CARRY_LIFT = 0.004
"""Between two stitches the hand carries the needle in an arc this high (m) along the next approach: a
needle carried straight across drags its tail through the wall (a contact a hand would feel and
avoid)."""


def pass_starts(passes: list[SuturingPass], gap: float = 0.5) -> list[float]:
    """When each pass of :func:`sequence_of_passes` begins (s)."""
    return np.cumsum([0.0] + [p.duration + gap for p in passes[:-1]]).tolist()


def sequence_of_passes(passes: list[SuturingPass], gap: float = 0.5) -> tuple[Trajectory, float]:
    """Several stitches one after another: a trajectory and its total duration (s).

    In the ``gap`` between two passes the jaws open, the hand moves to the needle's
    original grip point and closes on it again (so the next pass holds the needle as
    the first did), then carries it to where the next approach begins. Every move is
    a smooth one (no pose jumps: a jump would be a tool and tip speed no hand makes).
    """
    if not passes:
        raise DeviceError("sequence_of_passes needs at least one pass")
    starts = pass_starts(passes, gap)
    total = float(starts[-1] + passes[-1].duration)
    last = len(passes) - 1
    stops: dict[int, tuple[Pose, Pose, Pose]] = {}

    def gap_stops(k: int) -> tuple[Pose, Pose, Pose]:
        """Where pass k ends, the grip point, where the next approach starts (once pass k is done: a
        hand that sees re-grasped the needle where it lay)."""
        if k not in stops:
            p, q = passes[k], passes[k + 1]
            stops[k] = (p.pose_and_grip(p.duration)[0], p.final_needle_pose, q.pose_and_grip(0.0)[0])
        return stops[k]

    def trajectory(t: float) -> tuple[Pose, bool]:
        k = min(max(bisect.bisect_right(starts, t) - 1, 0), last)  # every haptic tick: plain floats
        local = t - starts[k]
        current = passes[k]
        if local <= current.duration:
            return current.pose_and_grip(local)
        end, grip, following = gap_stops(k)
        phase = (local - current.duration) / gap
        if phase < 0.2:
            return end, False  # open the jaws
        if phase < 0.4:
            return blend_poses(end, grip, (phase - 0.2) / 0.2), False  # to the grip point, open
        if phase < 0.5:
            return grip, True  # close on the needle
        # carry it to the next approach in an arc over the wall, so the needle's tail clears it
        fraction = (phase - 0.5) / 0.5
        carried = blend_poses(grip, following, fraction)
        rise = CARRY_LIFT * math.sin(math.pi * fraction) * passes[k + 1].approach
        return Pose.unchecked(carried.position + rise, carried.rotation), True

    def see_needle(needle_pose: Callable[[], Pose] | None) -> None:
        for one in passes:
            one.see_needle(needle_pose)
        stops.clear()

    trajectory.see_needle = see_needle  # type: ignore[attr-defined]
    return trajectory, total


def blend_poses(start: Pose, stop: Pose, fraction: float) -> Pose:
    """The pose ``fraction`` (0-1) of the way from ``start`` to ``stop`` along a smooth move: the
    position on the straight line, the rotation about the one axis that turns start into stop,
    both with zero speed at the ends (a cosine profile)."""
    w = 0.5 - 0.5 * math.cos(math.pi * min(max(fraction, 0.0), 1.0))
    if w >= 1.0:
        return stop
    relative = start.rotation.T @ stop.rotation
    axis = np.array(
        [relative[2, 1] - relative[1, 2], relative[0, 2] - relative[2, 0], relative[1, 0] - relative[0, 1]]
    )
    # atan2 of sine and cosine: acos alone loses small angles (1e-9 rad rounds to 0)
    angle = math.atan2(0.5 * float(np.linalg.norm(axis)), (float(np.trace(relative)) - 1.0) / 2.0)
    if np.linalg.norm(axis) < 1e-9 and angle > 1.0:  # a half turn: the axis from (R + I) / 2
        symmetric = (relative + np.eye(3)) / 2.0
        axis = symmetric[:, int(np.argmax(np.diag(symmetric)))]
    if angle < 1e-15:
        rotation = start.rotation
    else:
        rotation = start.rotation @ rotation_about(axis / np.linalg.norm(axis), w * angle)
    position = start.position + w * (stop.position - start.position)
    return Pose.unchecked(position, rotation)


def planned_exits(needle: Needle, collision, bites: list[tuple]) -> NDArray[np.float64]:
    """(k, 3) where ``needle``, planned square on each of ``bites`` ((entry, normal, bite_direction)
    each) and turned through a pass's insertion, crosses out of the wall of ``collision`` (a
    :class:`sim.collision.CollisionMesh`, at rest; m): what a real-time run solves ahead for."""
    sites = []
    for entry, normal, bite_direction in bites:
        plan = SuturingPass(needle, entry, normal, bite_direction)
        vertices = needle.world_vertices(plan.turned(math.radians(plan.p.insertion_arc_deg)))
        hits = collision.query(vertices)
        if len(hits):
            sites.append(hits.points(*segment_ends(vertices))[~hits.entering])
    return np.concatenate(sites) if sites else np.zeros((0, 3))
