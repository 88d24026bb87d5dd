"""The haptic tick's force path in one compiled call: holder publish, force interpolation at the
force delay, the device's scale factor, the safety filter, and the haptic log.

:class:`CompiledForcePath` runs :mod:`sim.runtime._haptic` (C) over the real-time runtime's shared
channels, with the same arithmetic as the Python channels and :class:`ForceSafety` (the tests drive
both with the same inputs and compare bit for bit). Events the filter raises are appended to the
:class:`ForceSafety`'s list with the same wording; after the loop :meth:`hand_back` gives the filter
its state again (the paced stop sequence continues from it).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from sim.runtime._haptic import ForcePath
from sim.runtime.safety import ForceSafety, clamped_event, nonfinite_event, recovered_event, watchdog_event
from sim.runtime.shared import SharedForceHistory, SharedHapticLog, SharedHolder
from sim.runtime.snapshots import HAPTIC_LOG_LAYOUT, HOLDER_LAYOUT

NONFINITE, WATCHDOG, RECOVERED, CLAMPED = 1, 2, 4, 8
"""The event bits ``ForcePath.tick`` returns (sim/runtime/_haptic.c)."""
HOLDER_FIELDS = ("seq", "time", "position", "rotation", "velocity", "grip")
"""The holder fields the compiled tick writes, in the order it takes their (start, width): their places
come from :data:`sim.runtime.snapshots.HOLDER_LAYOUT`, the slot's one declaration."""
LOG_FIELDS = ("time", "position", "grip", "force")
"""The haptic log's fields the compiled tick writes, in the order it takes their (start, width)
(:data:`sim.runtime.snapshots.HAPTIC_LOG_LAYOUT`)."""
EVENT_MAGNITUDE, EVENT_SILENCE = 7, 8
"""State cells naming an event's values: the clamped magnitude (N), the FEM layer's silence (s)."""


class CompiledForcePath:
    """One haptic tick's force path over the shared channels (see the module docstring)."""

    def __init__(
        self,
        holder: SharedHolder,
        forces: SharedForceHistory,
        log: SharedHapticLog,
        safety: ForceSafety,
        force_delay: float,
        haptic_scale: float,
    ) -> None:
        self.safety = safety
        self.state = safety.state_cells()
        self.force = np.zeros(3)  # the tick's force command, rewritten every tick
        ring, counter = forces.cells
        rows, count = log.cells
        limits, settings = safety.limits, safety.settings
        parameters = (
            settings.stall_timeout,
            settings.ramp_time,
            limits.max_force,
            limits.max_force_rate,
            safety.tick,
            force_delay,
            haptic_scale,
        )
        places = HOLDER_LAYOUT.spans(HOLDER_FIELDS)
        row = (HAPTIC_LOG_LAYOUT.size, HAPTIC_LOG_LAYOUT.spans(LOG_FIELDS))
        self._kernel = ForcePath(
            holder.cells, ring, counter, rows, count, self.state, self.force, parameters, places, row
        )

    def tick(
        self,
        now: float,
        position: NDArray[np.float64],
        rotation: NDArray[np.float64],
        velocity: NDArray[np.float64],
        grip: bool,
    ) -> NDArray[np.float64]:
        """The safe force for this tick (N; the same array every tick: copy it to keep it)."""
        events = self._kernel.tick(now, position, rotation, velocity, grip)
        if events:
            self._report(now, events)
        return self.force

    def warm(self, now: float) -> None:
        """Run the tick's reads and arithmetic without writing anything (in the wait before a
        deadline): the next tick then finds its code and cells in the caches."""
        self._kernel.warm(now)

    def _report(self, now: float, events: int) -> None:
        """The filter's new events, in :class:`ForceSafety`'s order and wording."""
        said = self.safety.events
        if events & NONFINITE:
            said.append(nonfinite_event(now))
        if events & WATCHDOG:
            said.append(watchdog_event(now, float(self.state[EVENT_SILENCE])))
        if events & RECOVERED:
            said.append(recovered_event(now))
        if events & CLAMPED:
            said.append(clamped_event(now, float(self.state[EVENT_MAGNITUDE]), self.safety.limits.max_force))

    def hand_back(self) -> None:
        """Give the :class:`ForceSafety` the state the compiled filter left."""
        self.safety.adopt(self.state)
