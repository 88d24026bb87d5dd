"""Tissue streams of a simulator session, derived from what was recorded and the task's tissue model.

The runtime records, every haptic tick, the needle tip, its speed, the needle state
and the nominated triangle with the barycentric weights of the contact point. While
the needle indents that triangle (state ``contact``) those determine the tissue's
state exactly: the runtime drove the triangle's nodes to ``b_k d`` with ``d`` the
tip's displacement from the contact point on the undeformed surface. From them and
the same tissue model this module derives:

- ``stretch``: the paper's stretch statistic lambda = 1 + |d| / h (h: wall depth under
  the contact, as the biphase model uses it), per tick of indentation;
- ``local_stress``: the largest von Mises stress (Pa) of the elements within
  :data:`NEAR_CONTACT_M` of the contact point, per tick of indentation;
- ``stress_field``: von Mises stress of every exterior triangle (centre, area) at
  the last tick of indentation before the first pierce, the moment of insertion.

Outside indentation (free, or with the needle through the wall) both per-tick
streams are NaN: the stretch statistic is defined for indentation, and a pierced
needle's load depends on its whole shape, which is not recorded.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from metrics.streams import SessionStreams
from sim.fem import BiphaseTissue, TissueModel
from sim.fem.fields import IndentationStress, TissueFieldReplay, contact_depth

NEAR_CONTACT_M = 0.002
"""Elements whose centroid lies within 2 mm of the contact point count as "near the contact"."""
CONTACT_STATE = 1
PIERCED_STATE = 2

Tissue = TissueModel | BiphaseTissue


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


def with_tissue_fields(streams: SessionStreams, tissue: Tissue) -> SessionStreams:
    """The streams with ``stretch``, ``local_stress`` and ``stress_field`` derived (see the module).

    Streams that already carry them, or lack what is needed (needle state, tip, contact
    triangle and weights, tip speed), are returned unchanged."""
    needed = ("needle_state", "tip_position", "contact_triangle", "contact_barycentric", "tip_speed")
    if any(getattr(streams, name) is None for name in needed):
        return streams
    if streams.stretch is not None or streams.local_stress is not None or streams.stress_field is not None:
        return streams
    mesh = tissue.mesh
    rest = mesh.points
    centroids = rest[mesh.tets].mean(axis=1)
    n = streams.time.size
    stretch = np.full(n, np.nan)
    local_stress = np.full(n, np.nan)
    stress_field = None
    pierced = np.flatnonzero(streams.needle_state == PIERCED_STATE)
    first_pierce = int(pierced[0]) if pierced.size else None
    operators: dict[tuple, IndentationStress] = {}
    for start, stop in indentation_runs(streams):
        triangle = int(streams.contact_triangle[start])
        nodes = mesh.surface_triangles[triangle]
        weights = streams.contact_barycentric[start]
        point = weights @ rest[nodes]
        tool_displacement = streams.tip_position[start:stop] - point
        stretch[start:stop] = 1.0 + np.linalg.norm(tool_displacement, axis=1) / contact_depth(tissue, nodes)
        key = (triangle, *weights.tolist())
        if key not in operators:
            near = np.flatnonzero(np.linalg.norm(centroids - point, axis=1) <= NEAR_CONTACT_M)
            near = (
                near if near.size else np.array([int(np.argmin(np.linalg.norm(centroids - point, axis=1)))])
            )
            operators[key] = IndentationStress(tissue, nodes, weights, near)
        speed = streams.tip_speed[start:stop]
        local_stress[start:stop] = operators[key].von_mises(tool_displacement, speed).max(axis=1)
        if first_pierce is not None and stop == first_pierce:
            stress_field = insertion_stress_field(
                tissue, nodes, weights, tool_displacement[-1], float(speed[-1])
            )
    return dataclasses.replace(
        streams,
        stretch=None if np.all(np.isnan(stretch)) else stretch,
        local_stress=None if np.all(np.isnan(local_stress)) else local_stress,
        stress_field=stress_field,
    )


def insertion_stress_field(
    tissue: Tissue,
    nodes: NDArray[np.int64],
    weights: NDArray[np.float64],
    tool_displacement: NDArray[np.float64],
    needle_speed: float,
) -> pd.DataFrame:
    """Von Mises stress (Pa) of each exterior triangle's element for one indentation state,
    with the triangle's centre (m) and area (m^2): the table the stress-localisation metrics read."""
    drive = np.outer(weights, tool_displacement)  # what the runtime drove the triangle's nodes to
    _, surface = TissueFieldReplay(tissue).state(nodes, drive, needle_speed)
    corners = tissue.mesh.points[tissue.mesh.surface_triangles]
    centres = corners.mean(axis=1)
    areas = 0.5 * np.linalg.norm(
        np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1
    )
    return pd.DataFrame(
        {"x": centres[:, 0], "y": centres[:, 1], "z": centres[:, 2], "area": areas, "von_mises": surface}
    )
