"""Always-on haptic safety: nothing the simulation computes reaches the device unchecked.

Per tick, in order: a non-finite target becomes zero (and an event); a stalled
FEM layer (no update for ``stall_timeout``) ramps the target smoothly to zero
over ``ramp_time`` (watchdog, with an event, recovering when FEM resumes); the
magnitude is clamped to the device's rated maximum; and the change from the last
commanded force is limited to the rated force rate. ``stop_sequence`` brings the
force to zero within the rate limit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from sim.devices.base import DeviceLimits


def nonfinite_event(now: float) -> tuple[float, str, str]:
    return (now, "nonfinite_force", "non-finite force from the simulation; sent zero")


def watchdog_event(now: float, silence: float) -> tuple[float, str, str]:
    return (now, "watchdog", f"FEM layer silent for {1e3 * silence:.0f} ms; ramping force to zero")


def recovered_event(now: float) -> tuple[float, str, str]:
    return (now, "watchdog_recovered", "FEM layer resumed")


def clamped_event(now: float, magnitude: float, limit: float) -> tuple[float, str, str]:
    return (now, "force_clamped", f"{1e3 * magnitude:.0f} mN clamped to the rated {1e3 * limit:.0f} mN")


@dataclass(frozen=True)
class SafetySettings:
    """stall_timeout (s) before the watchdog acts; ramp_time (s) to bring force to zero."""

    stall_timeout: float = 0.05
    ramp_time: float = 0.1


class ForceSafety:
    """Turns the force the simulation wants into the force the device may be sent."""

    def __init__(
        self, limits: DeviceLimits, settings: SafetySettings | None = None, tick: float = 1e-3
    ) -> None:
        self.limits = limits
        self.tick = tick
        self.settings = settings or SafetySettings()
        self._last = (0.0, 0.0, 0.0)
        self.last_time: float | None = None
        self.watchdog_since: float | None = None
        self._clamping = False
        self._nonfinite = False
        self.events: list[tuple[float, str, str]] = []

    def filter(self, now: float, target: NDArray[np.float64], fem_time: float | None) -> NDArray[np.float64]:
        """The safe force for this tick (N). Plain-float arithmetic: a few microseconds."""
        fx, fy, fz = target.tolist()
        if not (math.isfinite(fx) and math.isfinite(fy) and math.isfinite(fz)):
            if not self._nonfinite:
                self.events.append(nonfinite_event(now))
            self._nonfinite = True
            fx = fy = fz = 0.0
        else:
            self._nonfinite = False
        gain = self._watchdog_gain(now, fem_time)
        fx, fy, fz = self._clamp(now, fx * gain, fy * gain, fz * gain)
        return self._rate_limit(now, fx, fy, fz)

    def _watchdog_gain(self, now: float, fem_time: float | None) -> float:
        stalled = fem_time is not None and now - fem_time > self.settings.stall_timeout
        if stalled and self.watchdog_since is None:
            self.watchdog_since = now
            self.events.append(watchdog_event(now, now - fem_time))
        elif not stalled and self.watchdog_since is not None:
            self.events.append(recovered_event(now))
            self.watchdog_since = None
        if self.watchdog_since is None:
            return 1.0
        return max(0.0, 1.0 - (now - self.watchdog_since) / self.settings.ramp_time)

    def _clamp(self, now: float, fx: float, fy: float, fz: float) -> tuple[float, float, float]:
        magnitude = math.sqrt(fx * fx + fy * fy + fz * fz)
        limit = self.limits.max_force
        if magnitude > limit:
            if not self._clamping:
                self.events.append(clamped_event(now, magnitude, limit))
            self._clamping = True
            scale = limit / magnitude
            return fx * scale, fy * scale, fz * scale
        self._clamping = False
        return fx, fy, fz

    def _rate_limit(self, now: float, fx: float, fy: float, fz: float) -> NDArray[np.float64]:
        # A clock that jumps forward must not license a force jump: at most one nominal tick.
        dt = 0.0 if self.last_time is None else min(max(now - self.last_time, 0.0), self.tick)
        self.last_time = now
        lx, ly, lz = self._last
        dx, dy, dz = fx - lx, fy - ly, fz - lz
        allowed = self.limits.max_force_rate * dt
        size = math.sqrt(dx * dx + dy * dy + dz * dz)
        if size > allowed:
            scale = allowed / size
            dx, dy, dz = dx * scale, dy * scale, dz * scale
            self._last = (lx + dx, ly + dy, lz + dz)
        else:
            self._last = (fx, fy, fz)  # exactly the target, so ramps end at exact zero
        return np.array(self._last)

    @property
    def last(self) -> NDArray[np.float64]:
        return np.array(self._last)

    def state_cells(self) -> NDArray[np.float64]:
        """The filter's state as the compiled force path keeps it (sim/runtime/_haptic.c): last force
        3, last time, watchdog since (NaN: None), clamping, non-finite, and two cells for events."""
        none = math.nan
        return np.array(
            [
                *self._last,
                none if self.last_time is None else self.last_time,
                none if self.watchdog_since is None else self.watchdog_since,
                float(self._clamping),
                float(self._nonfinite),
                0.0,
                0.0,
            ]
        )

    def adopt(self, cells: NDArray[np.float64]) -> None:
        """Take back the state the compiled force path left (see :meth:`state_cells`)."""
        x, y, z, last_time, since, clamping, nonfinite = cells[:7].tolist()
        self._last = (x, y, z)
        self.last_time = None if math.isnan(last_time) else last_time
        self.watchdog_since = None if math.isnan(since) else since
        self._clamping, self._nonfinite = bool(clamping), bool(nonfinite)

    def stop_sequence(self, now: float, tick: float) -> list[tuple[float, NDArray[np.float64]]]:
        """Forces (time, force) that bring the output to exactly zero within the rate limit."""
        out = []
        t = now
        while self._last != (0.0, 0.0, 0.0):
            t += tick
            out.append((t, self._rate_limit(t, 0.0, 0.0, 0.0)))
            if len(out) > 100000:
                break
        return out
