"""Pieces shared by the in-process and shared-memory channels: log column views, force interpolation."""

from __future__ import annotations

import bisect

import numpy as np
from numpy.typing import NDArray

from sim.runtime.snapshots import HAPTIC_LOG_LAYOUT

_AT = HAPTIC_LOG_LAYOUT.at
_ROW_ORDER: slice | NDArray[np.int64] = np.r_[_AT.time, _AT.position, _AT.grip, _AT.force]
"""A row's places for (time, x, y, z, grip, fx, fy, fz): one assignment a tick, in any declared order
(a plain slice when the declaration is in this order: a fancy index costs 0.9 us more a tick)."""
if np.array_equal(_ROW_ORDER, np.arange(HAPTIC_LOG_LAYOUT.size)):
    _ROW_ORDER = slice(None)


class HapticColumns:
    """Named columns over ``self._data`` rows (:data:`sim.runtime.snapshots.HAPTIC_LOG_LAYOUT`) up to
    ``self.count``."""

    _data: NDArray[np.float64]
    count: int

    @property
    def time(self) -> NDArray[np.float64]:
        return self._data[: self.count, _AT.time]

    @property
    def position(self) -> NDArray[np.float64]:
        return self._data[: self.count, _AT.position]

    @property
    def grip(self) -> NDArray[np.float64]:
        return self._data[: self.count, _AT.grip]

    @property
    def force(self) -> NDArray[np.float64]:
        return self._data[: self.count, _AT.force]


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


class ForceHistory:
    """The FEM layer's recent (time, force) outputs, interpolated by the haptic layer.

    Plain lists with bisection: pushes arrive in time order, the oldest are
    dropped beyond ``capacity``; both sides touch it in microseconds.
    """

    def __init__(self, capacity: int = 256) -> None:
        self._times: list[float] = []
        self._forces: list[tuple[float, float, float]] = []
        self._capacity = capacity

    def push(self, time: float, force: NDArray[np.float64]) -> None:
        times, forces = self._times, self._forces
        fx, fy, fz = force.tolist()
        times.append(time)
        forces.append((fx, fy, fz))
        if len(times) > 2 * self._capacity:
            del times[: self._capacity], forces[: self._capacity]

    @property
    def latest_time(self) -> float | None:
        return self._times[-1] if self._times else None

    def at(self, time: float) -> NDArray[np.float64]:
        """Force at ``time``: linear between the two outputs around it, held at the ends."""
        times, forces = self._times, self._forces
        return interpolate_force(times, forces, time)


class HapticLog(HapticColumns):
    """Every haptic tick: time, holder position, grip, force sent, in growing preallocated arrays."""

    def __init__(self, capacity: int = 1 << 16) -> None:
        self._data = np.empty((capacity, HAPTIC_LOG_LAYOUT.size))
        self.count = 0

    def append(self, time: float, position: NDArray, grip: bool, force: NDArray) -> None:
        if self.count == len(self._data):
            self._data = np.concatenate([self._data, np.empty_like(self._data)])
        x, y, z = position.tolist()
        fx, fy, fz = force.tolist()
        self._data[self.count, _ROW_ORDER] = (time, x, y, z, float(grip), fx, fy, fz)
        self.count += 1
