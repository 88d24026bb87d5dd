"""Per-layer loop telemetry in preallocated arrays (in shared memory for the real-time run's processes:
:class:`SharedTelemetry`): when each step started and how long it took."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:  # annotations of the run's result only
    from sim.needle.events import NeedleEvent
    from sim.runtime.logs import HapticLog
    from sim.runtime.shared import Arena
    from sim.runtime.snapshots import RuntimeEvent


@dataclass(frozen=True)
class LayerSummary:
    """Achieved rate (Hz), period and compute-time percentiles (s), late steps."""

    layer: str
    steps: int
    rate_hz: float
    period_p50: float
    period_p99: float
    period_max: float
    compute_p50: float
    compute_p99: float
    compute_max: float
    missed_deadlines: int
    periods_over_2ms: int
    periods_over_3ms: int

    def as_dict(self) -> dict[str, float | int | str]:
        return dict(self.__dict__)


def pct(values: NDArray[np.float64], q: float) -> float:
    return float(np.percentile(values, q)) if len(values) else 0.0


class LoopTelemetry:
    """Start times and compute durations of one layer's steps."""

    def __init__(self, layer: str, period: float, capacity: int = 1 << 16) -> None:
        self.layer = layer
        self.period = period
        self._starts = np.empty(capacity)
        self._computes = np.empty(capacity)
        self._count = 0

    def record(self, start: float, compute: float) -> None:
        if self._count == len(self._starts):
            self._starts = np.concatenate([self._starts, np.empty_like(self._starts)])
            self._computes = np.concatenate([self._computes, np.empty_like(self._computes)])
        self._starts[self._count] = start
        self._computes[self._count] = compute
        self._count += 1

    @property
    def starts(self) -> NDArray[np.float64]:
        return self._starts[: self._count]

    @property
    def computes(self) -> NDArray[np.float64]:
        return self._computes[: self._count]

    def summary(self) -> LayerSummary:
        starts, computes = self.starts, self.computes
        periods = np.diff(starts) if len(starts) > 1 else np.zeros(1)
        span = starts[-1] - starts[0] if len(starts) > 1 else 0.0
        rate = (len(starts) - 1) / span if span > 0 else 0.0
        return LayerSummary(
            self.layer,
            len(starts),
            rate,
            pct(periods, 50),
            pct(periods, 99),
            float(periods.max()),
            pct(computes, 50),
            pct(computes, 99),
            float(computes.max()) if len(computes) else 0.0,
            int(np.sum(periods > 1.5 * self.period)),
            int(np.sum(periods > 2e-3)),
            int(np.sum(periods > 3e-3)),
        )


LAYERS = ("haptic", "fem", "graphics", "display")


@dataclass
class RunResult:
    """How a run ended and what it produced."""

    stop_reason: str
    end_time: float
    events: list[NeedleEvent | RuntimeEvent]
    telemetry: dict[str, LayerSummary]
    haptic: HapticLog
    error: str | None = None
    error_layer: str | None = None
    wall_seconds: float = 0.0

    @property
    def completed(self) -> bool:
        return self.stop_reason == "completed"


class SharedTelemetry:
    """Start and compute times of the haptic process's steps."""

    @staticmethod
    def doubles(capacity: int) -> int:
        """Its size in the arena: ``capacity`` (period, compute) pairs and a count."""
        return capacity * 2 + 1

    def __init__(self, arena: Arena, capacity: int) -> None:
        self._data = arena.take(capacity, 2)
        self._count = arena.take(1)

    def record(self, start: float, compute: float) -> None:
        index = int(self._count[0])
        if index < len(self._data):
            self._data[index] = (start, compute)
            self._count[0] = index + 1

    @property
    def starts(self) -> NDArray[np.float64]:
        return self._data[: int(self._count[0]), 0]

    @property
    def computes(self) -> NDArray[np.float64]:
        return self._data[: int(self._count[0]), 1]
