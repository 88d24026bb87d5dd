"""Where each bite went: stitch-placement metrics against the task's wound edge and target marks.

A stitch starts at a ``pierce`` event; its entry point is the pierced surface point (the event's
triangle and barycentric weights on the tissue mesh, exact, where the tip itself is already some
way into the wall when the puncture force is reached). Its exit point is the ``exit`` event that
follows before the next pierce, if any: the surface point where the tip came out. An exit whose
surface faces the task's far (luminal) side is a full-thickness bite; one through another face
(the wound's cut edge) missed the intima: a partial-thickness bite.

The task's geometry comes with the session (header ``placement``, written from the task library
when the session was recorded): a point on the wound edge and the unit normal of the wound plane
pointing from the tissue into the wound gap, the target bite (distance from the edge, m), the
target entry and exit marks, and the outward normal of the far surface. The bite distance of a
point p is its distance from the wound plane, (e - p) . n_wound.

Scoring entry and exit points against marked targets follows the AMBF surgical robotics
challenge's needle entry/exit scoring against hole centres (Munawar et al. 2022, IEEE RA-L);
bite distance and full thickness are what vascular technique teaches and OSATS raters judge
under "respect for tissue" (Martin et al. 1997, Br J Surg 84:273).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from metrics.errors import MetricsError

FAR_SURFACE_COSINE = 0.7
"""An exit face whose outward normal is within 45 deg of the far surface's counts as full thickness."""

STITCH_COLUMNS = (
    "stitch",
    "pierce_time",
    "exit_time",
    "entry_x",
    "entry_y",
    "entry_z",
    "exit_x",
    "exit_y",
    "exit_z",
    "exit_nx",
    "exit_ny",
    "exit_nz",
    "entry_nx",
    "entry_ny",
    "entry_nz",
)


@dataclass(frozen=True)
class PlacementTargets:
    """A task's wound edge and target marks (SI units); see the module docstring."""

    wound_point: NDArray[np.float64]
    wound_normal: NDArray[np.float64]
    target_bite: float
    entry_targets: NDArray[np.float64]
    exit_targets: NDArray[np.float64]
    far_normal: NDArray[np.float64]
    target_exit_bite: float
    """The exit's target distance from the edge (m): the entry's unless the task states its own
    (through a curved wall a straight bite ends nearer the edge on the inside)."""
    wound_direction: NDArray[np.float64] | None = None
    """Unit vector along the wound (a row of stitches progresses along it), if the task states it."""
    target_spacing: float | None = None
    """The target distance between successive stitches along the wound (m), if the task asks a row."""

    @classmethod
    def from_attributes(cls, attributes: dict[str, Any]) -> PlacementTargets | None:
        """The session's targets from its header's ``placement`` (None when it has none); a
        malformed one is a MetricsError naming the field."""
        given = attributes.get("placement")
        if given is None:
            return None
        if not isinstance(given, dict):
            raise MetricsError("the session's placement must be an object")

        def vector(name: str, shape: tuple[int, ...]) -> NDArray[np.float64]:
            try:
                value = np.asarray(given[name], dtype=np.float64)
            except (KeyError, TypeError, ValueError):
                raise MetricsError(f"the session's placement lacks a numeric {name!r}") from None
            if value.shape[-len(shape) :] != shape or not np.all(np.isfinite(value)):
                raise MetricsError(f"placement {name!r} must be finite with shape (..., {shape[-1]})")
            return value

        normals = [vector(name, (3,)) for name in ("wound_normal", "far_normal")]
        for name, normal in zip(("wound_normal", "far_normal"), normals, strict=True):
            if not math.isclose(float(np.linalg.norm(normal)), 1.0, rel_tol=1e-6):
                raise MetricsError(f"placement {name!r} must be a unit vector")
        bite = _distance(given, "target_bite_m")
        exit_bite = _distance(given, "target_exit_bite_m") if "target_exit_bite_m" in given else bite
        direction = vector("wound_direction", (3,)) if "wound_direction" in given else None
        if direction is not None and not math.isclose(float(np.linalg.norm(direction)), 1.0, rel_tol=1e-6):
            raise MetricsError("placement 'wound_direction' must be a unit vector")
        spacing = _distance(given, "target_spacing_m") if "target_spacing_m" in given else None
        return cls(
            vector("wound_point", (3,)),
            normals[0],
            bite,
            vector("entry_targets", (3,)).reshape(-1, 3),
            vector("exit_targets", (3,)).reshape(-1, 3),
            normals[1],
            exit_bite,
            direction,
            spacing,
        )

    def bite_distance(self, points: NDArray[np.float64]) -> NDArray[np.float64]:
        """Distance (m) of points from the wound plane, positive on the tissue's side."""
        return (self.wound_point - np.asarray(points, dtype=np.float64)) @ self.wound_normal


def _distance(given: dict[str, Any], name: str) -> float:
    try:
        value = float(given[name])
    except (KeyError, TypeError, ValueError):
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise MetricsError(f"placement {name!r} must be a positive distance (m)")
    return value


def stitch_points(events: pd.DataFrame, mesh) -> pd.DataFrame:
    """One row per pierce (columns :data:`STITCH_COLUMNS`): the entry point and entry face's outward
    normal of each pierce, and the exit point and exit face's outward normal of the exit that
    follows it (NaN without one). A pierce in through the far (luminal) surface is a back-wall catch,
    not a stitch (:meth:`StitchPlacement.of` tells them apart with the task's far normal)."""
    rows = []
    current: dict[str, float] | None = None
    for event in events.itertuples(index=False):
        if event.kind not in ("pierce", "exit"):
            continue
        weights = np.array([getattr(event, f"bary_{k}", np.nan) for k in range(3)], dtype=np.float64)
        triangle = int(event.triangle)
        if not (0 <= triangle < len(mesh.surface_triangles)) or not np.all(np.isfinite(weights)):
            continue  # a recording without the point (older schema or a foreign source)
        point = weights @ mesh.points[mesh.surface_triangles[triangle]]
        if event.kind == "pierce":
            current = {"stitch": len(rows), "pierce_time": float(event.time), "exit_time": math.nan}
            current.update(zip(("entry_x", "entry_y", "entry_z"), point.tolist(), strict=True))
            current.update({c: math.nan for c in STITCH_COLUMNS[6:12]})
            normal = mesh.surface_normals[triangle]
            current.update(zip(("entry_nx", "entry_ny", "entry_nz"), normal.tolist(), strict=True))
            rows.append(current)
        elif current is not None and math.isnan(current["exit_x"]):
            current["exit_time"] = float(event.time)
            current.update(zip(("exit_x", "exit_y", "exit_z"), point.tolist(), strict=True))
            normal = mesh.surface_normals[triangle]
            current.update(zip(("exit_nx", "exit_ny", "exit_nz"), normal.tolist(), strict=True))
    return pd.DataFrame(rows, columns=list(STITCH_COLUMNS))


STITCH_QUANTITIES = (
    "entry_bite",
    "exit_bite",
    "entry_to_target",
    "exit_to_target",
    "full_thickness",
    "track_offset",
    "swept_area",
    "wound_edge_stress",
)
"""What is kept per stitch: bite distances and distances to target (m), full thickness (1 or 0),
and how the needle went through the wall (:mod:`metrics.signals.passage`: m, m^2, Pa; NaN for a session
recorded without its scene)."""


@dataclass(frozen=True)
class StitchPlacement:
    """Per-stitch placement against the targets (m; NaN where the stitch has no exit)."""

    entry_bite: NDArray[np.float64]
    exit_bite: NDArray[np.float64]
    entry_to_target: NDArray[np.float64]
    exit_to_target: NDArray[np.float64]
    full_thickness: NDArray[np.float64]  # 1 through the far surface, 0 another face, NaN no exit
    target_bite: float
    target_exit_bite: float
    spacing: NDArray[np.float64]
    """Distances (m) along the wound between successive stitches' entry points (empty when the task
    states no wound direction or there is one stitch)."""
    target_spacing: float | None
    track_offset: NDArray[np.float64]
    swept_area: NDArray[np.float64]
    wound_edge_stress: NDArray[np.float64]
    back_wall_catches: int = 0
    """Pierces in through the far (luminal) surface: the needle caught the vessel's back wall."""
    marks: int = 0
    """The task's target entry marks: the stitches it asks for."""

    @classmethod
    def of(cls, pierces: pd.DataFrame, targets: PlacementTargets) -> StitchPlacement:
        entry_normals = _columns(pierces, ("entry_nx", "entry_ny", "entry_nz"))
        catch = entry_normals @ targets.far_normal >= FAR_SURFACE_COSINE
        stitches = pierces[~catch]
        entry = stitches[["entry_x", "entry_y", "entry_z"]].to_numpy(dtype=np.float64)
        exit_ = stitches[["exit_x", "exit_y", "exit_z"]].to_numpy(dtype=np.float64)
        normals = stitches[["exit_nx", "exit_ny", "exit_nz"]].to_numpy(dtype=np.float64)
        facing = (normals @ targets.far_normal >= FAR_SURFACE_COSINE).astype(float)
        through = np.where(np.isnan(normals[:, 0]), np.nan, facing)
        passage = {name: _columns(stitches, (name,))[:, 0] for name in STITCH_QUANTITIES[5:]}
        return cls(
            targets.bite_distance(entry),
            targets.bite_distance(exit_),
            _nearest(entry, targets.entry_targets),
            _nearest(exit_, targets.exit_targets),
            through,
            targets.target_bite,
            targets.target_exit_bite,
            _spacing(entry, targets.wound_direction),
            targets.target_spacing,
            **passage,
            back_wall_catches=int(catch.sum()),
            marks=len(targets.entry_targets),
        )

    def table(self) -> pd.DataFrame:
        """One row per stitch (1, 2, ...), one column per :data:`STITCH_QUANTITIES` (SI units)."""
        return pd.DataFrame(
            {
                "stitch": np.arange(1, self.entry_bite.size + 1),
                **{name: getattr(self, name) for name in STITCH_QUANTITIES},
            }
        )


def stitch_table(streams) -> pd.DataFrame | None:
    """The session's per-stitch placement (:meth:`StitchPlacement.table`), or None when it has no
    stitch points or its task declares no targets."""
    targets = PlacementTargets.from_attributes(dict(streams.attributes))
    if targets is None or streams.stitches is None or streams.stitches.empty:
        return None
    return StitchPlacement.of(streams.stitches, targets).table()


def _columns(table: pd.DataFrame, names: tuple[str, ...]) -> NDArray[np.float64]:
    """(n, len(names)) of the table's columns, NaN for a column it lacks (an older table)."""
    return np.column_stack(
        [
            table[name].to_numpy(dtype=np.float64) if name in table.columns else np.full(len(table), np.nan)
            for name in names
        ]
    ).reshape(len(table), len(names))


def _spacing(entries: NDArray[np.float64], direction: NDArray[np.float64] | None) -> NDArray[np.float64]:
    """|Successive differences| of the entry points' positions along the wound, in stitch order."""
    if direction is None or len(entries) < 2:
        return np.zeros(0)
    return np.abs(np.diff(entries @ direction))


def _nearest(points: NDArray[np.float64], marks: NDArray[np.float64]) -> NDArray[np.float64]:
    """Distance (m) from each point to its nearest mark (NaN for a NaN point or no marks)."""
    if not len(marks):
        return np.full(len(points), np.nan)
    distances = np.linalg.norm(points[:, None, :] - marks[None, :, :], axis=2)
    return distances.min(axis=1)


MARK_COLOURS = ((0.25e-3, (40, 170, 60)), (0.75e-3, (240, 150, 20)), (math.inf, (210, 30, 30)))
"""A bite mark's colour by its distance from its target mark: green within 0.25 mm, orange within
0.75 mm, red farther (replay frames)."""


def mark_colour(distance: float) -> tuple[int, int, int]:
    """RGB of a bite that landed ``distance`` (m) from its mark (grey when unknown)."""
    if not math.isfinite(distance):
        return (128, 128, 128)
    return next(colour for limit, colour in MARK_COLOURS if distance <= limit)


def mean_or_nan(values: NDArray[np.float64]) -> float:
    """Mean of the finite values (NaN when there are none)."""
    finite = values[np.isfinite(values)]
    return float(finite.mean()) if finite.size else math.nan
