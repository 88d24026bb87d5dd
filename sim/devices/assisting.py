"""The scripted subordinate hand: forceps that take the wound's edge before each bite, evert it (lift
it out, so the needle can enter square inside the edge: PAPER.md, "the subordinate hand is used mainly
to facilitate this access") and let go once the needle is pulled through; with a trainee's faults
(grasping late, lifting too far, not grasping at all, a shaky hold). A trajectory for
:class:`sim.devices.scripted.ScriptedDevice`, timed against the needle hand's passes."""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sim.devices.base import DeviceError, Trajectory
from sim.devices.suturing import SuturingPass, SuturingPassParameters, pass_starts
from sim.needle import Pose

LET_GO = 0.85
"""The jaws open this far (0-1) through the needle hand's pull-through phase: the needle is then clear
of the wall, and the pass's last moves are the needle hand's alone."""


@dataclass(frozen=True)
class AssistingHandParameters:
    """Skill parameters of the scripted subordinate hand.

    grasps: whether the hand takes the edge at all (a novice may suture one-handed).
    grasp_delay: how late (s) the jaws close after the moment an expert's do (0.3 of the needle's
        approach): a late hand closes during the insertion.
    eversion: how far (m) the grasped edge is lifted out of the wall.
    hover: how far above the edge (m) the open forceps wait between bites.
    tremor_amplitude (m), tremor_frequency (Hz): the hand's tremor.
    seed: the tremor's phases.
    """

    grasps: bool = True
    grasp_delay: float = 0.0
    eversion: float = 0.12e-3
    hover: float = 0.004
    tremor_amplitude: float = 0.0
    tremor_frequency: float = 7.0
    seed: int = 0

    def __post_init__(self) -> None:
        if not 0.0 <= self.eversion <= 0.01:
            raise DeviceError(f"eversion must be 0-10 mm; got {self.eversion * 1e3:g} mm")
        if not 0.0 <= self.grasp_delay <= 30.0:
            raise DeviceError(f"grasp_delay must be 0-30 s; got {self.grasp_delay:g} s")


@dataclass(frozen=True)
class ScriptedHands:
    """A scripted session's two hands: the needle hand's pass parameters and the subordinate hand's
    (None: a one-handed session)."""

    needle: SuturingPassParameters = field(default_factory=SuturingPassParameters)
    assisting: AssistingHandParameters | None = None


def edge_grasp(
    entry: ArrayLike, normal: ArrayLike, wound_point: ArrayLike, wound_normal: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(where the jaws close, the unit direction they lift the edge) for a bite entering at ``entry``
    (outward surface ``normal``) beside a wound whose edge plane passes through ``wound_point`` with
    ``wound_normal`` pointing from the tissue into the gap: the edge's rim nearest the entry (its
    projection on that plane), lifted straight out of the wall (along the normal: a wound gapes a
    fraction of a millimetre, so an edge pulled into the gap would be pushed into the other edge)."""
    entry, n = np.asarray(entry, dtype=np.float64), _unit(normal)
    w = _unit(wound_normal)
    rim = entry + float((np.asarray(wound_point, dtype=np.float64) - entry) @ w) * w
    return rim, n


def _unit(v: ArrayLike) -> NDArray[np.float64]:
    v = np.asarray(v, dtype=np.float64)
    norm = float(np.linalg.norm(v))
    if not norm > 0:
        raise DeviceError("the assisting hand's directions must be non-zero vectors")
    return v / norm


def _blend(start: NDArray, stop: NDArray, fraction: float) -> NDArray:
    w = 0.5 - 0.5 * math.cos(math.pi * min(max(fraction, 0.0), 1.0))
    return start + w * (stop - start)


def assisting_hand(
    passes: list[SuturingPass],
    grasps: list[tuple[ArrayLike, ArrayLike]],
    parameters: AssistingHandParameters | None = None,
    gap: float = 0.5,
) -> Trajectory:
    """The subordinate hand's trajectory over ``passes`` (as :func:`sequence_of_passes` times them,
    ``gap`` s apart): for pass k it waits open ``hover`` above ``grasps[k]`` (rim, lift direction),
    reaches the rim and closes by 0.3 of the needle's approach (plus ``grasp_delay``), lifts the edge
    by ``eversion`` over the next half of the approach, holds it still through the insertion, the
    needle hand's re-grasp and the pull-through (a wall let go with the needle in it would spring back
    around a needle that stays), and opens near the pull's end (:data:`LET_GO`); then moves to wait
    above the next bite's rim. The needle hand aims at the bite as planned at rest: the lifted wall
    meets it sooner and tilted, and the entry angle is measured against the wall where it is."""
    p = parameters or AssistingHandParameters()
    if len(grasps) != len(passes) or not passes:
        raise DeviceError("the assisting hand needs one edge grasp per pass")
    starts = pass_starts(passes, gap)
    rims = [np.asarray(rim, dtype=np.float64) for rim, _ in grasps]
    lifts = [_unit(lift) for _, lift in grasps]
    above = [rim + p.hover * lift for rim, lift in zip(rims, lifts, strict=True)]
    everted = [rim + p.eversion * lift for rim, lift in zip(rims, lifts, strict=True)]
    phase = np.random.default_rng(p.seed).uniform(0, 2 * math.pi, size=3)
    omega = 2 * math.pi * p.tremor_frequency * np.array([1.0, 1.17, 0.89])
    rotation = np.eye(3)
    last = len(passes) - 1

    def trajectory(t: float) -> tuple[Pose, bool]:
        k = min(max(bisect.bisect_right(starts, t) - 1, 0), last)
        local, current = t - starts[k], passes[k]
        approach = current.phases["approach"][1]
        closes = 0.3 * approach + p.grasp_delay
        held = False
        pull_start, pull_end = current.phases["pull"]
        if p.grasps and pull_start + LET_GO * (pull_end - pull_start) < local <= current.duration:
            position = everted[k]  # open where it let go
        elif local > current.duration:  # open, on the way to wait above the next rim
            if k == last:
                position = everted[k] if p.grasps else above[k]
            else:
                start = everted[k] if p.grasps else above[k]
                position = _blend(start, above[k + 1], (local - current.duration) / (0.5 * gap))
        elif not p.grasps:
            position = above[k]
        elif local < closes:
            position = _blend(above[k], rims[k], local / closes)
        else:
            held = True
            position = _blend(rims[k], everted[k], (local - closes) / (0.5 * approach))
        if p.tremor_amplitude:  # a hand shakes holding or not
            position = position + p.tremor_amplitude * np.sin(omega * t + phase)
        return Pose.unchecked(position, rotation), held

    return trajectory
