"""Derived quantities shared by several metrics, computed once per session on first use."""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import NDArray

from metrics.signals.kinematics import LDLJ_CUTOFF_HZ, Movements, UniformMotion, find_movements
from metrics.signals.placement import PlacementTargets, StitchPlacement
from metrics.streams import SessionStreams

MOTION_RATE_HZ = 100.0
"""Speed-based metrics and path length use the path low-passed at 6 Hz and then decimated to at most
100 Hz (1 kHz adds nothing below 6 Hz)."""


@dataclass(frozen=True)
class Insertion:
    """One needle insertion: pierce time, the end of its passage, the episode's first contact.

    entry_angle_deg: the needle tip's angle to the inward normal when it first touched
    the tissue in this episode (the bite's entry angle; the pierce comes after the
    wrist has already turned the needle further).
    """

    contact_time: float
    pierce_time: float
    end_time: float
    entry_angle_deg: float


class SessionContext:
    """Lazily derived views of one session's streams, shared by the registered metrics."""

    def __init__(self, streams: SessionStreams, insertion_radius: float = 0.005) -> None:
        self.streams = streams
        self.insertion_radius = insertion_radius

    @cached_property
    def motion(self) -> UniformMotion:
        rate = min(MOTION_RATE_HZ, self.streams.sample_rate)
        return UniformMotion.of(self.streams.time, self.streams.tool_position, rate)

    @cached_property
    def movements(self) -> Movements:
        return find_movements(self.motion)

    @cached_property
    def jerk_motion(self) -> UniformMotion:
        """The path at its own rate, low-passed only at :data:`LDLJ_CUTOFF_HZ`: the basis of LDLJ."""
        return UniformMotion.of(self.streams.time, self.streams.tool_position, None, LDLJ_CUTOFF_HZ)

    @cached_property
    def insertions(self) -> list[Insertion]:
        """Pierce events with their episode's first contact and the passage's end (exit, release or end)."""
        events = self.streams.events
        kinds = events["kind"].to_numpy()
        times = events["time"].to_numpy(dtype=np.float64)
        angles = events["entry_angle_deg"].to_numpy(dtype=np.float64)
        result = []
        episode_start = episode_angle = math.nan
        for k, kind in enumerate(kinds):
            if kind == "contact_start" and math.isnan(episode_start):
                episode_start, episode_angle = times[k], angles[k]
            elif kind == "pierce":
                later = np.flatnonzero(
                    (times > times[k]) & np.isin(kinds, ("exit", "pull_through", "pierce"))
                )
                end = times[later[0]] if later.size else self.streams.time[-1]
                start = episode_start if not math.isnan(episode_start) else times[k]
                angle = episode_angle if not math.isnan(episode_angle) else angles[k]
                result.append(Insertion(start, times[k], float(end), angle))
                episode_start = episode_angle = math.nan
            elif kind == "contact_end":
                episode_start = episode_angle = math.nan
        return result

    @cached_property
    def placement(self):
        """Each stitch's placement against the task's targets
        (:class:`metrics.signals.placement.StitchPlacement`), or None without stitch points or targets."""

        targets = PlacementTargets.from_attributes(dict(self.streams.attributes))
        stitches = self.streams.stitches
        if targets is None or stitches is None or stitches.empty:
            return None
        return StitchPlacement.of(stitches, targets)

    @cached_property
    def insertion_point(self) -> NDArray[np.float64] | None:
        """Where the needle first pierced (m): the session's attribute, else the tip at the first pierce."""
        given = self.streams.attributes.get("insertion_point")
        if given is not None:
            return np.asarray(given, dtype=np.float64)
        if not self.insertions or self.streams.tip_position is None:
            return None
        return self.tip_at(self.insertions[0].pierce_time)

    def tip_at(self, time: float) -> NDArray[np.float64]:
        tip = self.streams.tip_position
        return np.array([np.interp(time, self.streams.time, tip[:, k]) for k in range(3)])

    @cached_property
    def tip_speed(self) -> NDArray[np.float64] | None:
        tip = self.streams.tip_position
        if tip is None:
            return None
        return np.linalg.norm(np.gradient(tip, self.streams.time, axis=0), axis=1)

    @cached_property
    def force_magnitude(self) -> NDArray[np.float64] | None:
        force = self.streams.force
        return None if force is None else np.linalg.norm(force, axis=1)

    @cached_property
    def in_tissue(self) -> NDArray[np.bool_]:
        """Samples where the needle touches or is inside the tissue (all samples without a state stream)."""
        state = self.streams.needle_state
        if state is None:
            return np.ones(self.streams.time.size, dtype=bool)
        return state > 0

    def window(self, start: float, end: float) -> NDArray[np.bool_]:
        time = self.streams.time
        return (time >= start) & (time <= end)

    def span(self, start: float, end: float) -> slice:
        """The samples with start <= time <= end, as a slice (time is sorted: two binary searches)."""
        time = self.streams.time
        return slice(int(np.searchsorted(time, start, "left")), int(np.searchsorted(time, end, "right")))
