"""The expert reference a session is compared with: one expert session, or several summarised.

Signals (force magnitude, tip speed, local stress) of every expert are carried onto
the reviewed session's own time axis through the phase + DTW alignment, so the
expert median and inter-quartile band follow the trainee's phases: at the trainee's
pierce the band shows what experts did at their pierce. The visual reference for
ghost and side-by-side views is the medoid expert (smallest total alignment cost to
the other experts).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from metrics.errors import MetricsError
from metrics.signals.alignment import PHASES, Alignment, align_sessions, decimated, phase_starts
from metrics.streams import SessionStreams

SIGNALS = {
    "force": ("force (mN)", 1e3),
    "tip_speed": ("tip speed (mm/s)", 1e3),
    "stress": ("local von Mises stress (kPa)", 1e-3),
}
"""Signal name -> (axis label, factor from SI to the plotted unit)."""


def signal_of(streams: SessionStreams, name: str) -> NDArray[np.float64] | None:
    """A session's signal in SI units (N, m/s, Pa), or None when it lacks the stream."""
    if name == "force":
        return None if streams.force is None else np.linalg.norm(streams.force, axis=1)
    if name == "tip_speed":
        if streams.tip_speed is not None:
            return streams.tip_speed
        if streams.tip_position is None:
            return None
        return np.linalg.norm(np.gradient(streams.tip_position, streams.time, axis=0), axis=1)
    if name == "stress":
        return streams.local_stress
    raise MetricsError(f"unknown signal {name!r}; known: {', '.join(SIGNALS)}")


@dataclass(frozen=True)
class Band:
    """Expert median and quartiles (SI units) on the reviewed session's time axis; NaN where no expert
    has data (e.g. stress outside indentation)."""

    median: NDArray[np.float64]
    lower: NDArray[np.float64]
    upper: NDArray[np.float64]


@dataclass(frozen=True)
class ExpertReference:
    """Expert sessions, the medoid among them, and each expert's alignment to the reviewed session."""

    experts: list[SessionStreams]
    medoid: SessionStreams
    alignments: list[Alignment]  # reviewed session -> each expert (at 100 Hz), in the order of ``experts``
    medoid_alignment: Alignment

    def band(self, session: SessionStreams, name: str) -> Band:
        """The experts' ``name`` signal carried onto ``session``'s time axis."""
        carried = []
        for expert, alignment in zip(self.experts, self.alignments, strict=True):
            values = signal_of(expert, name)
            if values is None:
                continue
            finite = np.isfinite(values)
            mapped = alignment.reference_time_at(session.time)
            column = np.interp(mapped, expert.time, np.where(finite, values, 0.0))
            # NaN where the expert had no value near the matched time (outside indentation for stress)
            known = np.interp(mapped, expert.time, finite.astype(float)) > 0.5
            carried.append(np.where(known, column, np.nan))
        if not carried:
            nan = np.full(session.time.size, np.nan)
            return Band(nan, nan, nan)
        stack = np.vstack(carried)
        with np.errstate(all="ignore"):
            has = np.isfinite(stack).any(axis=0)
            quartiles = np.full((3, stack.shape[1]), np.nan)
            if has.any():
                quartiles[:, has] = np.nanpercentile(stack[:, has], [25, 50, 75], axis=0)
        return Band(quartiles[1], quartiles[0], quartiles[2])

    def phase_band(self, name: str) -> dict[str, tuple[float, float, float]]:
        """Per phase, the experts' (lower quartile, median, upper quartile) of a signal, pooled."""
        pooled: dict[str, list[NDArray]] = {phase: [] for phase in PHASES}
        for expert in self.experts:
            values = signal_of(expert, name)
            if values is None or expert.needle_state is None:
                continue
            bounds = phase_starts(expert.needle_state, expert.time)
            for k, phase in enumerate(PHASES):
                if not np.isfinite(bounds[k]):
                    continue
                later = bounds[k + 1 : -1]
                stop = later[np.isfinite(later)][0] if np.isfinite(later).any() else np.inf
                inside = (expert.time >= bounds[k]) & (expert.time < stop)
                pooled[phase].append(values[inside])
        out = {}
        for phase, parts in pooled.items():
            values = np.concatenate(parts) if parts else np.zeros(0)
            values = values[np.isfinite(values)]
            if values.size:
                q1, q2, q3 = np.percentile(values, [25, 50, 75])
                out[phase] = (float(q1), float(q2), float(q3))
        return out


def expert_reference(session: SessionStreams, experts: list[SessionStreams]) -> ExpertReference:
    """Align ``session`` to every expert and pick the medoid expert for the visual comparison."""
    if not experts:
        raise MetricsError("no expert sessions to compare with")
    # aligned at 100 Hz: 10 ms is finer than a video frame, and 1 kHz sessions align 10x faster
    coarse = [decimated(expert) for expert in experts]
    if len(experts) == 1:
        medoid = experts[0]
    else:
        costs = np.zeros(len(experts))
        for i, a in enumerate(coarse):
            for j, b in enumerate(coarse):
                if i != j:
                    costs[i] += align_sessions(b, a).cost
        medoid = experts[int(np.argmin(costs))]
    mine = decimated(session)
    alignments = [align_sessions(mine, expert) for expert in coarse]
    return ExpertReference(list(experts), medoid, alignments, alignments[experts.index(medoid)])
