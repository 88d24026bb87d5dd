"""What the metrics read: one session's streams as arrays, from any source.

A :class:`SessionStreams` holds the time base and the dominant tool's positions
(always), and whatever else the source has: needle tip, force, tissue stress and
stretch, needle state, subordinate hand, grip, events. Metrics that need a stream
the session lacks are NaN for it, never guessed.

Builders: :func:`from_recorded` (a recorder session), :func:`from_frame` (any table
with time and tool positions, e.g. a CSV from another simulator).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from metrics.errors import MetricsError
from metrics.signals.tracked import measured_path
from recorder.scene import read_scene

EVENT_COLUMNS = ("time", "kind", "entry_angle_deg", "tip_speed", "triangle")


def _empty_events() -> pd.DataFrame:
    return pd.DataFrame(
        {
            "time": pd.Series(dtype=float),
            "kind": pd.Series(dtype=str),
            "entry_angle_deg": pd.Series(dtype=float),
            "tip_speed": pd.Series(dtype=float),
            "triangle": pd.Series(dtype=int),
        }
    )


@dataclass(frozen=True, eq=False)
class NeedleFrames:
    """The needle and the tissue's drive at the graphics rate (the recorded scene stream).

    times (F,) s; state (F,) as ``needle_state``; needle (F, V, 3) m, the needle's vertices tip
    first; drives: per frame None (the tissue untouched) or (contact node ids (k,), their
    intended displacements (k, 3) m, the biphase soft share or nan); tip_speed (F,) m/s."""

    times: NDArray[np.float64]
    state: NDArray[np.int8]
    needle: NDArray[np.float64]
    drives: list
    tip_speed: NDArray[np.float64]

    def __post_init__(self) -> None:
        frames = len(self.times)
        shapes = (len(self.state), len(self.needle), len(self.drives), len(self.tip_speed))
        if any(n != frames for n in shapes) or self.needle.ndim != 3 or self.needle.shape[2:] != (3,):
            raise MetricsError(f"needle frames disagree in length or shape: {frames} times, {shapes}")

    @classmethod
    def from_scene(cls, scene) -> NeedleFrames:
        """From a scene table (:data:`recorder.scene.SCENE_SCHEMA`)."""
        flat = scene.column("needle").combine_chunks()
        vertices = len(flat[0]) // 3 if len(flat) else 0
        nodes = scene.column("drive_nodes").to_pylist()
        intended = scene.column("drive_intended").to_pylist()
        shares = scene.column("drive_soft_share").to_numpy(zero_copy_only=False).astype(np.float64)
        drives = [
            (np.asarray(n, np.int64), np.asarray(d, np.float64).reshape(-1, 3), float(share)) if n else None
            for n, d, share in zip(nodes, intended, shares, strict=True)
        ]
        return cls(
            scene.column("time").to_numpy().astype(np.float64),
            scene.column("state").to_numpy().astype(np.int8),
            flat.flatten().to_numpy().reshape(-1, vertices, 3).astype(np.float64),
            drives,
            scene.column("tip_speed").to_numpy().astype(np.float64),
        )


@dataclass(frozen=True, eq=False)
class SessionStreams:
    """One session's samples (SI units) and events.

    time: (n,) s, non-decreasing. tool_position: (n, 3) m, the dominant hand's
    needle holder. Optional (n,)-aligned arrays: tip_position (n, 3) m; force (n, 3) N
    sent to the device (the tissue's reaction); needle_state (n,) 0 free, 1 contact,
    2 pierced, 3 exited; local_stress (n,) Pa, the largest von Mises stress near the
    contact; stretch (n,) the paper's stretch statistic lambda = 1 + |d|/h (d the tip's
    indentation of the wall, h the wall depth under the contact); contact_triangle (n,)
    exterior triangle touched (-1 none) with contact_barycentric (n, 3) weights of the
    contact point; tip_speed (n,) m/s;
    subordinate_displacement (n, 3) m from the subordinate hand's start; grip (n,)
    1 closed; forceps_jaw (n,) the subordinate hand's jaws, 1 closed; grasp_force (n, 3) N the
    forceps' force on the tissue they hold (zero when they hold none). events: DataFrame with at least
    time and kind. stress_field: optional table of the tissue surface at the moment of insertion
    (columns x, y, z, area, von_mises; m, m², Pa). force_limit: the device's rated clamp (N), if known.
    stitches: optional table of each stitch's entry and exit points on the tissue surface
    (:func:`metrics.signals.placement.stitch_points`, derived with the tissue mesh), with how the
    needle went through the wall where the scene was recorded (:mod:`metrics.signals.passage`).
    needle_frames: the recorded scene (:class:`NeedleFrames`), if any.
    """

    session_id: str
    time: NDArray[np.float64]
    tool_position: NDArray[np.float64]
    participant_id: str | None = None
    label: str | None = None
    tip_position: NDArray[np.float64] | None = None
    force: NDArray[np.float64] | None = None
    needle_state: NDArray[np.int8] | None = None
    local_stress: NDArray[np.float64] | None = None
    stretch: NDArray[np.float64] | None = None
    subordinate_displacement: NDArray[np.float64] | None = None
    grip: NDArray[np.int8] | None = None
    forceps_jaw: NDArray[np.float64] | None = None
    grasp_force: NDArray[np.float64] | None = None
    events: pd.DataFrame = field(default_factory=_empty_events)
    stress_field: pd.DataFrame | None = None
    contact_triangle: NDArray[np.int32] | None = None
    contact_barycentric: NDArray[np.float64] | None = None
    tip_speed: NDArray[np.float64] | None = None
    force_limit: float | None = None
    attributes: Mapping[str, Any] = field(default_factory=dict)
    stitches: pd.DataFrame | None = None
    needle_frames: NeedleFrames | None = None

    def __post_init__(self) -> None:
        time = np.ascontiguousarray(self.time, dtype=np.float64)
        if time.ndim != 1 or time.size < 2:
            raise MetricsError(
                f"session {self.session_id!r}: time needs at least 2 samples; got {time.shape}"
            )
        if not np.all(np.isfinite(time)):
            raise MetricsError(f"session {self.session_id!r}: time has non-finite values")
        if np.any(np.diff(time) < 0):
            k = int(np.flatnonzero(np.diff(time) < 0)[0])
            raise MetricsError(f"session {self.session_id!r}: time goes backwards at sample {k + 1}")
        object.__setattr__(self, "time", time)
        n = time.size
        for name, width in (
            ("tool_position", 3),
            ("tip_position", 3),
            ("force", 3),
            ("subordinate_displacement", 3),
            ("forceps_jaw", 1),
            ("grasp_force", 3),
            ("needle_state", 1),
            ("local_stress", 1),
            ("stretch", 1),
            ("grip", 1),
            ("contact_triangle", 1),
            ("contact_barycentric", 3),
            ("tip_speed", 1),
        ):
            value = getattr(self, name)
            if value is None:
                continue
            array = np.asarray(value)
            expected = (n, width) if width > 1 else (n,)
            if array.shape != expected:
                raise MetricsError(
                    f"session {self.session_id!r}: {name} has shape {array.shape}, expected {expected}"
                )
            object.__setattr__(self, name, np.ascontiguousarray(array))
        events = self.events
        missing = [c for c in ("time", "kind") if c not in events.columns]
        if missing:
            raise MetricsError(f"session {self.session_id!r}: events lack column(s) {', '.join(missing)}")
        events = events.sort_values("time", kind="stable").reset_index(drop=True)
        for column in EVENT_COLUMNS:
            if column not in events.columns:
                events[column] = -1 if column == "triangle" else np.nan
        object.__setattr__(self, "events", events)

    @property
    def duration(self) -> float:
        return float(self.time[-1] - self.time[0])

    @property
    def sample_rate(self) -> float:
        """Median sampling rate (Hz)."""
        return float(1.0 / np.median(np.diff(self.time)))

    def event_times(self, kind: str) -> NDArray[np.float64]:
        return self.events.loc[self.events["kind"] == kind, "time"].to_numpy(dtype=np.float64)

    def has(self, stream: str) -> bool:
        if stream == "events":
            return len(self.events) > 0
        if stream in ("time", "tool_position"):
            return True
        return getattr(self, stream) is not None


def from_recorded(session, participant_id: str | None = None, label: str | None = None) -> SessionStreams:
    """Streams of a :class:`recorder.Session` (header ``session_id``/``participant``/``label`` if present)."""
    samples = session.samples
    header = dict(session.header)

    def columns(*names: str) -> NDArray[np.float64]:
        return np.column_stack([samples.column(n).to_numpy() for n in names]).astype(np.float64)

    def column(name: str) -> NDArray:
        return samples.column(name).to_numpy()

    events = session.events.to_pandas()
    metadata = header
    stress = column("local_stress").astype(np.float64)
    stretch = column("stretch").astype(np.float64)
    # the tissue's force on the needle where recorded (schema 2); older sessions kept only what the
    # device was sent, which equals it unless the device clamped or scaled it
    reaction = columns("reaction_x", "reaction_y", "reaction_z")
    force = reaction if np.all(np.isfinite(reaction)) else columns("force_x", "force_y", "force_z")

    scene = read_scene(session)
    # the subordinate hand where one was recorded (schema 4, its tool point known); a one-handed
    # session's zero displacement would read as a perfectly still hand, so it is left unmeasured
    two_handed = bool(np.all(np.isfinite(columns("sub_x", "sub_y", "sub_z"))))
    time = column("time").astype(np.float64)
    tool = columns("tool_x", "tool_y", "tool_z")
    if str(header.get("device", "")).startswith("camera"):  # measured poses only, smoothed
        labels = column("tool_tracking")
        tool = measured_path(time, tool, labels)
        metadata = dict(metadata, tool_measured_fraction=float(np.mean(labels == 0)))
    subordinate = columns("sub_dx", "sub_dy", "sub_dz") if two_handed else None
    if subordinate is not None and str(header.get("sub_device", "")) == "camera":  # the same for the forceps
        subordinate = measured_path(time, subordinate, column("sub_tracking"))
    return SessionStreams(
        session_id=str(header.get("session_id", session.path.name)),
        participant_id=participant_id or metadata.get("participant_id"),
        label=label or metadata.get("label"),
        time=time,
        tool_position=tool,
        tip_position=columns("tip_x", "tip_y", "tip_z"),
        force=force,
        needle_state=column("pierced").astype(np.int8),
        local_stress=None if np.all(np.isnan(stress)) else stress,
        stretch=None if np.all(np.isnan(stretch)) else stretch,
        subordinate_displacement=subordinate,
        grip=column("grip").astype(np.int8),
        forceps_jaw=column("sub_jaw").astype(np.float64) if two_handed else None,
        grasp_force=columns("grasp_fx", "grasp_fy", "grasp_fz") if two_handed else None,
        contact_triangle=column("contact_triangle").astype(np.int32),
        contact_barycentric=columns("bary_0", "bary_1", "bary_2"),
        tip_speed=column("tip_speed").astype(np.float64),
        events=events,
        force_limit=metadata.get("force_limit"),
        attributes=metadata,
        needle_frames=None if scene is None or scene.num_rows == 0 else NeedleFrames.from_scene(scene),
    )


def from_frame(
    frame: pd.DataFrame,
    session_id: str,
    *,
    time: str = "time",
    tool_position: Sequence[str] = ("tool_x", "tool_y", "tool_z"),
    tip_position: Sequence[str] | None = None,
    force: Sequence[str] | None = None,
    subordinate_position: Sequence[str] | None = None,
    participant_id: str | None = None,
    label: str | None = None,
    events: pd.DataFrame | None = None,
    position_scale: float = 1.0,
) -> SessionStreams:
    """Streams from any table with a time column and tool positions (other columns optional).

    position_scale converts the table's length unit to metres (e.g. 1e-3 for mm).
    subordinate_position: absolute positions of the other hand; stored as displacement
    from its first sample.
    """
    missing = [c for c in (time, *tool_position) if c not in frame.columns]
    for group in (tip_position, force, subordinate_position):
        missing += [c for c in (group or ()) if c not in frame.columns]
    if missing:
        raise MetricsError(f"session {session_id!r}: table lacks column(s) {', '.join(missing)}")

    def block(names: Sequence[str] | None, scale: float = 1.0) -> NDArray[np.float64] | None:
        if names is None:
            return None
        return frame[list(names)].to_numpy(dtype=np.float64) * scale

    subordinate = block(subordinate_position, position_scale)
    if subordinate is not None:
        subordinate = subordinate - subordinate[0]
    return SessionStreams(
        session_id=session_id,
        participant_id=participant_id,
        label=label,
        time=frame[time].to_numpy(dtype=np.float64),
        tool_position=block(tool_position, position_scale),
        tip_position=block(tip_position, position_scale),
        force=block(force),
        subordinate_displacement=subordinate,
        events=events if events is not None else _empty_events(),
    )
