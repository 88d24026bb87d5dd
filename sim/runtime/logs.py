"""Pieces shared by the in-process and shared-memory channels: log column views, force interpolation."""

from __future__ import annotations

import bisect

import numpy as np
from numpy.typing import NDArray


class HapticColumns:
    """Named columns over ``self._data`` rows [time, position 3, grip, force 3] up to ``self.count``."""

    _data: NDArray[np.float64]
    count: int

    @property
    def time(self) -> NDArray[np.float64]:
        return self._data[: self.count, 0]

    @property
    def position(self) -> NDArray[np.float64]:
        return self._data[: self.count, 1:4]

    @property
    def grip(self) -> NDArray[np.float64]:
        return self._data[: self.count, 4]

    @property
    def force(self) -> NDArray[np.float64]:
        return self._data[: self.count, 5:8]


def interpolate_force(
    times: list[float], forces: list[tuple[float, float, float]], time: float
) -> NDArray[np.float64]:
    """Force at ``time`` from time-sorted samples: linear between neighbours, held at the ends."""
    if not times:
        return np.zeros(3)
    k = bisect.bisect_right(times, time)
    if k == 0:
        return np.array(forces[0])
    if k == len(times):
        return np.array(forces[-1])
    w = (time - times[k - 1]) / (times[k] - times[k - 1])
    a, b = forces[k - 1], forces[k]
    return np.array([a[0] + w * (b[0] - a[0]), a[1] + w * (b[1] - a[1]), a[2] + w * (b[2] - a[2])])
