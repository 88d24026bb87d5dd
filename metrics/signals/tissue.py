"""Tissue streams of a simulator session, derived from what was recorded and the task's tissue model.

The runtime streams ``local_stress`` and ``stretch`` live, at the FEM layer's rate, whenever
the needle touches or is inside the tissue. It also records, every haptic tick, the needle
tip, its speed, the needle state and the nominated triangle with the barycentric weights of
the contact point, and the header records the needle-force law (:func:`session_forces`). While
the needle indents that triangle (state ``contact``) those determine the tissue's state
exactly, so this module derives from them, with the same tissue model and the same code the
runtime used (the force kernel of :mod:`sim.needle.load`, or the paper's barycentric drive
``b_k d`` for sessions recorded under it):

- ``stretch``: the largest stretch (deformed over rest length) of the edges of the elements within
  1 mm of the contact in the displacement field the display draws, per tick of indentation;
- ``local_stress``: the largest von Mises stress (Pa) near the contact, per tick of
  indentation (for sessions that did not stream it; for those that did, the derivation is
  the test oracle of the live stream);
- ``stress_field``: von Mises stress of every exterior triangle (centre, area) at the last
  tick of indentation before the first pierce, the moment of insertion.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from metrics.signals.passage import passage_columns
from metrics.signals.placement import stitch_points
from metrics.streams import SessionStreams
from sim.fem import Tissue
from sim.fem.fields import IndentationStress, LocalStress, TissueFieldReplay
from sim.needle import Needle
from sim.needle.forces import NeedleForces
from sim.needle.load import KernelLoad, kernel_factory, kernel_step, mindlin_ratio, tissue_poisson_ratio

NEAR_CONTACT_M = 0.002
"""With the paper's rule, elements whose centroid lies within 2 mm of the contact point count as "near
the contact" (the force kernel's local stress is that of the elements within 1 mm, as the runtime
streams it)."""
WIRE_RADIUS = 0.5 * Needle.curved().wire_diameter
"""The runner's needle (a 0.25 mm wire)."""
CONTACT_STATE = 1
PIERCED_STATE = 2


def indentation_runs(streams: SessionStreams) -> list[tuple[int, int]]:
    """[start, stop) sample ranges of uninterrupted indentation of one contact point."""
    state = streams.needle_state
    triangle = streams.contact_triangle
    weights = streams.contact_barycentric
    indenting = (state == CONTACT_STATE) & (triangle >= 0) & np.all(np.isfinite(weights), axis=1)
    if not indenting.any():
        return []
    change = np.zeros(len(state), dtype=bool)
    change[1:] = (triangle[1:] != triangle[:-1]) | np.any(weights[1:] != weights[:-1], axis=1)
    before = np.r_[False, indenting[:-1]]
    after = np.r_[indenting[1:], False]
    starts = np.flatnonzero(indenting & (change | ~before))
    stops = np.flatnonzero(indenting & (np.r_[change[1:], True] | ~after)) + 1
    return list(zip(starts.tolist(), stops.tolist(), strict=True))


def session_forces(streams: SessionStreams) -> NeedleForces:
    """The needle-force law a session ran under (its header's ``needle_forces``; sessions recorded
    before the header said so ran under the source paper's barycentric rule)."""
    recorded = streams.attributes.get("needle_forces")
    return NeedleForces.paper() if recorded is None else NeedleForces.from_dict(dict(recorded))


@dataclass(frozen=True)
class _Contact:
    """A nominated contact as the runtime had it, rebuilt from the recorded triangle and weights."""

    triangle: int
    nodes: NDArray[np.int64]
    barycentric: NDArray[np.float64]
    point: NDArray[np.float64]
    normal: NDArray[np.float64]


def with_tissue_fields(
    streams: SessionStreams, tissue: Tissue, forces: NeedleForces | None = None
) -> SessionStreams:
    """The streams with ``stretch``, ``local_stress``, ``stress_field`` and ``stitches`` (each bite's
    entry and exit points, :func:`metrics.signals.placement.stitch_points`, and from a recorded scene how
    the needle went through the wall, :mod:`metrics.signals.passage`) derived (see the module).

    forces: the needle-force law the session ran under (default: :func:`session_forces`). Per-tick
    streams the runtime recorded are kept; only what is missing is derived. Streams that lack what
    is needed (needle state, tip, contact triangle and weights, tip speed) are returned unchanged."""
    if streams.stitches is None and len(streams.events):  # where each bite went, on this mesh
        stitches = stitch_points(streams.events, tissue.mesh)
        if streams.needle_frames is not None:  # and how the needle went through the wall
            stitches = passage_columns(stitches, streams.needle_frames, tissue)
        streams = dataclasses.replace(streams, stitches=stitches)
    needed = ("needle_state", "tip_position", "contact_triangle", "contact_barycentric", "tip_speed")
    if any(getattr(streams, name) is None for name in needed):
        return streams
    per_tick_known = streams.stretch is not None or streams.local_stress is not None
    if per_tick_known and streams.stress_field is not None:
        return streams
    forces = forces or session_forces(streams)
    indentation = _KernelIndentation if forces.load == "kernel" else _BarycentricIndentation
    n = streams.time.size
    stretch = np.full(n, np.nan)
    local_stress = np.full(n, np.nan)
    stress_field = None
    pierced = np.flatnonzero(streams.needle_state == PIERCED_STATE)
    first_pierce = int(pierced[0]) if pierced.size else None
    models: dict[tuple, object] = {}
    mesh = tissue.mesh
    for start, stop in indentation_runs(streams):
        triangle = int(streams.contact_triangle[start])
        weights = streams.contact_barycentric[start]
        key = (triangle, *weights.tolist())
        if key not in models:
            nodes = mesh.surface_triangles[triangle]
            contact = _Contact(
                triangle, nodes, weights, weights @ mesh.points[nodes], mesh.surface_normals[triangle]
            )
            models[key] = indentation(tissue, contact, forces)
        model = models[key]
        tips = streams.tip_position[start:stop]
        speed = streams.tip_speed[start:stop]
        if not per_tick_known or (first_pierce is not None and stop == first_pierce):
            run_stretch, run_stress = model.per_tick(tips, speed)
            if not per_tick_known:
                stretch[start:stop], local_stress[start:stop] = run_stretch, run_stress
        if first_pierce is not None and stop == first_pierce and streams.stress_field is None:
            stress_field = model.stress_field(tips, float(speed[-1]))
    if per_tick_known:
        return dataclasses.replace(streams, stress_field=stress_field)
    return dataclasses.replace(
        streams,
        stretch=None if np.all(np.isnan(stretch)) else stretch,
        local_stress=None if np.all(np.isnan(local_stress)) else local_stress,
        stress_field=stress_field,
    )


class _BarycentricIndentation:
    """The paper's rule: the triangle's nodes driven to b_k d; the stress of the elements within
    :data:`NEAR_CONTACT_M` from the linear operators of :class:`IndentationStress`."""

    def __init__(self, tissue: Tissue, contact: _Contact, forces: NeedleForces) -> None:
        self.tissue, self.contact = tissue, contact
        centroids = tissue.mesh.points[tissue.mesh.tets].mean(axis=1)
        distance = np.linalg.norm(centroids - contact.point, axis=1)
        near = np.flatnonzero(distance <= NEAR_CONTACT_M)
        near = near if near.size else np.array([int(np.argmin(distance))])
        self.operator = IndentationStress(tissue, contact.nodes, contact.barycentric, near)
        self.handle = tissue.contact(contact.nodes)
        self.local = LocalStress(tissue, contact.nodes, np.eye(3 * len(contact.nodes)), [contact.point])

    def per_tick(self, tips: NDArray, speed: NDArray) -> tuple[NDArray, NDArray]:
        tool_displacement = tips - self.contact.point
        stretch = np.empty(len(tips))
        for k, (d, v) in enumerate(zip(tool_displacement, speed, strict=True)):
            reactions = self.handle.reaction_forces(np.outer(self.contact.barycentric, d), d, float(v))
            stretch[k] = self.local.stretch(reactions.reshape(-1))
        return stretch, self.operator.von_mises(tool_displacement, speed).max(axis=1)

    def stress_field(self, tips: NDArray, speed: float) -> pd.DataFrame:
        drive = np.outer(self.contact.barycentric, tips[-1] - self.contact.point)
        return _surface_table(self.tissue, self.contact.nodes, drive, speed, None)


class _KernelIndentation:
    """The force kernel (:mod:`sim.needle.load`): the same load, contact law
    (:func:`sim.needle.load.kernel_step`: stick-slip, loading-only speed effect, tearing) and local
    operator the runtime built at the first touch, stepped through the run's ticks in order (a tick
    repeating the last one's tip and speed is the same FEM step, held)."""

    def __init__(self, tissue: Tissue, contact: _Contact, forces: NeedleForces) -> None:
        self.tissue, self.contact, self.forces = tissue, contact, forces
        self.load = KernelLoad(tissue, kernel_factory(forces, WIRE_RADIUS, [contact]))
        self.operator = self.load.local_stress(tissue)
        self.ratio = mindlin_ratio(tissue_poisson_ratio(tissue))
        self._last: tuple[NDArray, float] | None = None

    def per_tick(self, tips: NDArray, speed: NDArray) -> tuple[NDArray, NDArray]:
        stretch, stress = np.empty(len(tips)), np.empty(len(tips))
        point, indentation = self.contact.point.copy(), 0.0
        held = np.zeros(len(tips), dtype=bool)
        held[1:] = np.all(tips[1:] == tips[:-1], axis=1) & (speed[1:] == speed[:-1])
        extra = np.zeros((1, 3))
        for k in range(len(tips)):
            if held[k]:
                stretch[k], stress[k] = stretch[k - 1], stress[k - 1]
                continue
            step = kernel_step(
                self.load,
                (tips[k] - point)[None, :],
                extra,
                float(speed[k]),
                indentation,
                self.forces,
                self.contact.normal,
                self.ratio,
            )
            point, indentation = point + step.shifts[0], step.indentation
            generalised = step.kernel_forces.reshape(-1)
            stress[k], _, stretch[k] = self.operator.measures(
                generalised, 1.0 / self.load.drive_scale(step.share)
            )
            self._last = (step.kernel_forces, step.share)
        return stretch, stress

    def stress_field(self, tips: NDArray, speed: float) -> pd.DataFrame:
        if self._last is None:
            self.per_tick(tips, np.full(len(tips), speed))
        kernel_forces, share = self._last
        drive = self.load.kernel_drive(kernel_forces, share)
        return _surface_table(self.tissue, self.load.nodes, drive, speed, share)


def _surface_table(tissue: Tissue, nodes, drive, speed: float, share: float | None) -> pd.DataFrame:
    """Von Mises stress (Pa) of each exterior triangle's element for one drive, with the triangle's
    centre (m) and area (m^2)."""
    _, surface = TissueFieldReplay(tissue).state(nodes, drive, speed, share)
    corners = tissue.mesh.points[tissue.mesh.surface_triangles]
    centres = corners.mean(axis=1)
    areas = 0.5 * np.linalg.norm(
        np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1
    )
    return pd.DataFrame(
        {"x": centres[:, 0], "y": centres[:, 1], "z": centres[:, 2], "area": areas, "von_mises": surface}
    )
