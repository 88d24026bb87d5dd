"""Pivot calibration: where an instrument's tip lies in its marker cube's frame.

The trainee rests the instrument's tip in a small dimple (a pencil mark on the table will do) and
pivots the instrument about it, tilting it in every direction. Every pose ``(R_i, t_i)`` of the cube
then maps the same unknown tip offset ``x`` (body frame) onto the same unknown pivot ``p`` (camera
frame): ``R_i x + t_i = p``. Stacked, ``[R_i  -I] [x; p] = -t_i`` is an ordinary linear least-squares
problem (the standard method of optical tracking, e.g. Yaniv, SPIE Medical Imaging 2015). The residual,
the RMS distance of each ``R_i x + t_i`` from ``p``, says how well the tip stayed put; the spread of
the poses' orientations says how well ``x`` is determined (a tip pivoted through a few degrees is
not located along the shaft at all).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from sim.errors import TrackingError
from sim.tracking.filters import rotation_vector

MIN_POSES = 20
MIN_SPREAD_DEG = 20.0
"""The poses must tilt at least this far from the first one (the widest of them)."""
MAX_RESIDUAL_M = 1.0e-3
"""A residual above 1 mm means the tip slipped, or the markers were poorly seen: done again."""


@dataclass(frozen=True)
class PivotResult:
    """The tip in the body frame (m), the pivot point in the camera frame (m), the RMS residual (m),
    the poses used and the widest tilt among them (deg)."""

    tip_offset: NDArray[np.float64]
    pivot: NDArray[np.float64]
    residual: float
    poses: int
    spread_deg: float


def pivot_calibration(rotations: NDArray[np.float64], translations: NDArray[np.float64]) -> PivotResult:
    """Solve for the tip offset from ``rotations`` (n, 3, 3) and ``translations`` (n, 3) of the body
    (camera <- body); refuse too few poses, too little tilt, or a tip that did not stay put."""
    rotations = np.asarray(rotations, dtype=np.float64)
    translations = np.asarray(translations, dtype=np.float64)
    n = len(rotations)
    if n < MIN_POSES:
        raise TrackingError(
            f"pivot calibration saw the instrument in {n} frames; it needs at least {MIN_POSES}: keep the "
            "markers in view while pivoting"
        )
    spread = _spread_deg(rotations)
    if spread < MIN_SPREAD_DEG:
        raise TrackingError(
            f"the instrument tilted only {spread:.0f} deg about its tip; pivot it at least "
            f"{MIN_SPREAD_DEG:.0f} deg in every direction, the tip resting in one place"
        )
    system = np.zeros((3 * n, 6))
    system[:, :3] = rotations.reshape(3 * n, 3)
    system[:, 3:] = -np.tile(np.eye(3), (n, 1))
    solution, *_ = np.linalg.lstsq(system, -translations.reshape(3 * n), rcond=None)
    tip, pivot = solution[:3], solution[3:]
    misses = np.einsum("nij,j->ni", rotations, tip) + translations - pivot
    residual = float(np.sqrt(np.mean(np.sum(misses**2, axis=1))))
    if residual > MAX_RESIDUAL_M:
        raise TrackingError(
            f"the pivot calibration's residual is {residual * 1e3:.2f} mm (at most "
            f"{MAX_RESIDUAL_M * 1e3:.1f} mm): the tip slipped, or the markers were poorly seen; rest the "
            "tip in a small dimple and pivot slowly in good light"
        )
    return PivotResult(tip, pivot, residual, n, spread)


def _spread_deg(rotations: NDArray[np.float64]) -> float:
    """The widest angle (deg) between a pose's orientation and the first pose's."""
    first = rotations[0]
    return max(math.degrees(float(np.linalg.norm(rotation_vector(r @ first.T)))) for r in rotations)
