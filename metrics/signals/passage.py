"""How the needle went through the wall, stitch by stitch: from the recorded scene (the needle's
vertices and the tissue's drive at the graphics rate) and each stitch's entry point.

A stitch's frames run from the last frame the needle was free before its pierce to the last
free frame before the next stitch's pierce (the last stitch: to the end). Per stitch:

- ``track_offset`` (m): mean, over the frames the needle is in the wall (pierced or exited),
  of the distance from the stitch's entry point to the needle's own curve. A needle turned
  along its curve slides through its hole and keeps this near zero; a levered needle pushes
  its body sideways through the wall (the lateral load on the wall is the same thing seen as
  force). Frames after the needle's tail has left the hole do not count.
- ``swept_area`` (m^2): tissue the needle sweeps beyond its own track, summed over successive
  in-wall frames as the sideways movement of the needle at the entry hole times the length of
  needle inside the wall (the tip's arc length from the hole, at most the entry-exit chord once
  out). PerkTutor's tissue-damage idea (Ungi et al. 2012, IEEE TBME 59:3475) on a curved needle.
- ``wound_edge_stress`` (Pa): the largest von Mises stress, over the stitch's frames with a drive,
  of the elements on the wound's cut faces (mesh node sets ``wound_a``/``wound_b``), from the
  recorded drive through the task's tissue model (:class:`sim.fem.fields.TissueFieldReplay`,
  the same linear far field the runtime solved). A bite too near the edge, or a levered needle,
  loads the edge.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from metrics.streams import NeedleFrames
from sim.fem.fields import TissueFieldReplay

PASSAGE_COLUMNS = ("track_offset", "swept_area", "wound_edge_stress")
IN_WALL = (2, 3)  # pierced, exited
FREE = 0


def stitch_frames(frames: NeedleFrames, pierce_times: NDArray[np.float64]) -> list[slice]:
    """Per stitch, the slice of frames that belong to it (see the module docstring)."""
    free = np.flatnonzero(frames.state == FREE)
    starts = []
    for time in pierce_times:
        before = free[frames.times[free] < time]
        starts.append(int(before[-1]) if before.size else 0)
    starts[0] = 0
    return [slice(a, b) for a, b in zip(starts, [*starts[1:], len(frames.times)], strict=True)]


class CurvePoint(NamedTuple):
    """The point of a polyline nearest a given point."""

    distance: float  # m, from the given point
    arc: float  # m, arc length from vertex 0
    past_tail: bool  # the nearest point is the polyline's last vertex
    point: NDArray[np.float64]  # the nearest point itself (m)
    direction: NDArray[np.float64]  # unit direction of the polyline there (zero on a null segment)


def nearest_point(vertices: NDArray[np.float64], point: NDArray[np.float64]) -> CurvePoint:
    """The point of the polyline ``vertices`` nearest ``point``."""
    a, b = vertices[:-1], vertices[1:]
    ab = b - a
    lengths2 = np.einsum("ij,ij->i", ab, ab)
    t = np.clip(np.einsum("ij,ij->i", point - a, ab) / np.where(lengths2 > 0, lengths2, 1.0), 0.0, 1.0)
    closest = a + t[:, None] * ab
    distances = np.linalg.norm(closest - point, axis=1)
    k = int(np.argmin(distances))
    length = math.sqrt(lengths2[k])
    arc = float(np.sqrt(lengths2[:k]).sum() + t[k] * length)
    direction = ab[k] / length if length > 0 else np.zeros(3)
    return CurvePoint(float(distances[k]), arc, bool(k == len(ab) - 1 and t[k] >= 1.0), closest[k], direction)


def nearest_on_curve(vertices: NDArray[np.float64], point: NDArray[np.float64]) -> tuple[float, float, bool]:
    """(distance (m) from ``point`` to the polyline, arc length from vertex 0 to the nearest point
    (m), whether the nearest point is the polyline's last vertex)."""
    nearest = nearest_point(vertices, point)
    return nearest.distance, nearest.arc, nearest.past_tail


def track_and_sweep(
    frames: NeedleFrames, window: slice, entry: NDArray[np.float64], chord: float
) -> tuple[float, float]:
    """(mean track offset (m), swept area (m^2)) of one stitch's frames; NaN, 0 when the needle was
    never in the wall there."""
    offsets, previous, area = [], None, 0.0
    for k in range(window.start, window.stop):
        if frames.state[k] not in IN_WALL:
            previous = None
            continue
        nearest = nearest_point(frames.needle[k], entry)
        if nearest.past_tail:
            previous = None
            continue
        offsets.append(nearest.distance)
        inside = min(nearest.arc, chord) if math.isfinite(chord) else nearest.arc
        if previous is not None:  # the crossing's movement across the needle (sliding along it is free)
            moved = nearest.point - previous
            area += float(np.linalg.norm(moved - (moved @ nearest.direction) * nearest.direction)) * inside
        previous = nearest.point
    return (float(np.mean(offsets)) if offsets else math.nan), area


class WoundEdgeStress:
    """Peak von Mises stress (Pa) of a tissue's wound-edge elements under recorded drives."""

    def __init__(self, tissue) -> None:

        self.elements = tissue.mesh.wound_edge_elements
        self._replay = TissueFieldReplay(tissue, elements=self.elements) if self.elements.size else None

    def stress(self, nodes: NDArray, drive: NDArray, tip_speed: float, share: float) -> NDArray:
        """Von Mises stress (Pa) of each of :attr:`elements` under one drive of the tissue."""
        if self._replay is None:
            return np.zeros(0)
        return self._replay.stress(nodes, drive, tip_speed, share)

    def peak(self, frames: NeedleFrames, window: slice) -> float:
        if self._replay is None:
            return math.nan
        peak = math.nan
        for k in range(window.start, window.stop):
            drive = frames.drives[k]
            if drive is None or not len(drive[0]):
                continue
            nodes, intended, share = drive
            stress = self._replay.stress(nodes, intended, float(frames.tip_speed[k]), share)
            peak = float(stress.max()) if math.isnan(peak) else max(peak, float(stress.max()))
        return peak


def passage_columns(stitches: pd.DataFrame, frames: NeedleFrames, tissue) -> pd.DataFrame:
    """``stitches`` (:func:`metrics.signals.placement.stitch_points`) with :data:`PASSAGE_COLUMNS` added."""
    result = stitches.copy()
    if stitches.empty:
        for name in PASSAGE_COLUMNS:
            result[name] = pd.Series(dtype=float)
        return result
    windows = stitch_frames(frames, stitches["pierce_time"].to_numpy(dtype=np.float64))
    entries = stitches[["entry_x", "entry_y", "entry_z"]].to_numpy(dtype=np.float64)
    exits = stitches[["exit_x", "exit_y", "exit_z"]].to_numpy(dtype=np.float64)
    edge = WoundEdgeStress(tissue) if tissue is not None else None
    rows = []
    for window, entry, exit_ in zip(windows, entries, exits, strict=True):
        chord = float(np.linalg.norm(exit_ - entry))  # nan without an exit
        offset, area = track_and_sweep(frames, window, entry, chord)
        rows.append((offset, area, math.nan if edge is None else edge.peak(frames, window)))
    values = np.array(rows, dtype=np.float64).reshape(-1, len(PASSAGE_COLUMNS))
    for k, name in enumerate(PASSAGE_COLUMNS):
        result[name] = values[:, k]
    return result
