"""Time alignment of two sessions: by task phase, then dynamic time warping on the needle-tip path.

A suturing pass has four phases, read off the needle state: ``approach`` (until the
tip first touches the wall), ``contact`` (indenting, until the first pierce),
``pierce`` (through the wall, until the tip exits) and ``exit`` (to the end). Phase
boundaries are matched to each other; within a phase the tip paths are aligned by
dynamic time warping (DTW), then refined to a continuous position along the other
path, so a copy of a path replayed at another, even varying, speed maps back to the
original's time exactly (up to the path's linear interpolation).

Everything here is a pure function of arrays.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from metrics.errors import MetricsError
from metrics.streams import SessionStreams

PHASES = ("approach", "contact", "pierce", "exit")
MAX_DTW_POINTS = 400
"""Each phase's path is resampled to at most this many points for the DTW (cost grows as its square)."""


@dataclass(frozen=True)
class Alignment:
    """A monotone map from one session's time to another's (s).

    times: (n,) sample times of the aligned session; reference_times: (n,) the matching
    time in the reference session. phase_bounds / reference_phase_bounds: start time of
    each phase in :data:`PHASES` (NaN if the session never reached it) and the end time.
    cost: mean distance (m) between matched tip positions.
    """

    times: NDArray[np.float64]
    reference_times: NDArray[np.float64]
    phase_bounds: NDArray[np.float64]
    reference_phase_bounds: NDArray[np.float64]
    cost: float

    def reference_time_at(self, time: ArrayLikeFloat) -> NDArray[np.float64]:
        """The reference session's time matching ``time`` in the aligned session."""
        return np.interp(time, self.times, self.reference_times)


ArrayLikeFloat = float | NDArray[np.float64]


def phase_starts(needle_state: NDArray, time: NDArray[np.float64]) -> NDArray[np.float64]:
    """Start time of each phase (approach, contact, pierce, exit) and the end time; NaN when not reached.

    needle_state: 0 free, 1 contact, 2 pierced, 3 exited (the recorder's coding)."""
    state = np.asarray(needle_state)
    bounds = np.full(len(PHASES) + 1, np.nan)
    bounds[0] = time[0]
    for k, code in enumerate((1, 2, 3), start=1):
        reached = np.flatnonzero(state >= code)
        if reached.size:
            bounds[k] = time[reached[0]]
    bounds[-1] = time[-1]
    # a later phase cannot start before an earlier one (state may fall back after a release)
    for k in range(2, len(PHASES)):
        if np.isfinite(bounds[k]) and np.isfinite(bounds[k - 1]):
            bounds[k] = max(bounds[k], bounds[k - 1])
    return bounds


def dtw_path(
    a: NDArray[np.float64], b: NDArray[np.float64]
) -> tuple[NDArray[np.int64], NDArray[np.int64], float]:
    """Classic DTW between point sequences a (n, d) and b (m, d) with Euclidean cost.

    Returns the warping path's index pairs (monotone, from (0, 0) to (n-1, m-1)) and its
    total cost. Each row of the cost matrix is one vectorised step: with
    a_j = c_ij + min(D[i-1, j-1], D[i-1, j]), D[i, j] = min(a_j, c_ij + D[i, j-1]) is a
    running minimum over cumulative sums, D[i, :] = C + minimum.accumulate(a - C)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    n, m = len(a), len(b)
    if n == 0 or m == 0:
        raise MetricsError("DTW needs two non-empty paths")
    cost = np.linalg.norm(a[:, None, :] - b[None, :, :], axis=-1)
    total = np.empty((n, m))
    total[0] = np.cumsum(cost[0])
    for i in range(1, n):
        previous = total[i - 1]
        diagonal_or_up = np.minimum(np.r_[np.inf, previous[:-1]], previous)
        running = np.cumsum(cost[i])
        total[i] = running + np.minimum.accumulate(cost[i] + diagonal_or_up - running)
    i, j = n - 1, m - 1
    rows, cols = [i], [j]
    while i > 0 or j > 0:
        if i == 0:
            j -= 1
        elif j == 0:
            i -= 1
        else:
            step = np.argmin((total[i - 1, j - 1], total[i - 1, j], total[i, j - 1]))
            if step == 0:
                i, j = i - 1, j - 1
            elif step == 1:
                i -= 1
            else:
                j -= 1
        rows.append(i)
        cols.append(j)
    return np.array(rows[::-1]), np.array(cols[::-1]), float(total[-1, -1])


def _resampled(count: int, limit: int) -> NDArray[np.int64]:
    return np.unique(np.linspace(0, count - 1, min(count, limit)).round().astype(np.int64))


def _project(points: NDArray, path: NDArray, seeds: NDArray[np.int64], window: int) -> NDArray[np.float64]:
    """For each point, the continuous index along the polyline ``path`` nearest to it, searched in the
    segments within ``window`` of its DTW seed."""
    segments = len(path) - 1
    if segments <= 0:
        return np.zeros(len(points))
    offsets = np.arange(-window, window + 1)
    candidates = np.clip(seeds[:, None] + offsets[None, :], 0, segments - 1)  # (n, w) segment ids
    start = path[candidates]
    direction = path[candidates + 1] - start
    length2 = np.einsum("nwk,nwk->nw", direction, direction)
    along = np.einsum("nwk,nwk->nw", points[:, None, :] - start, direction)
    fraction = np.clip(np.divide(along, length2, out=np.zeros_like(along), where=length2 > 0), 0.0, 1.0)
    nearest = start + fraction[..., None] * direction
    distance = np.linalg.norm(points[:, None, :] - nearest, axis=-1)
    # equally near segments (a tip at rest) are told apart by nearness to the DTW seed: 1e-12 m per sample
    distance += 1e-12 * np.abs(candidates - seeds[:, None])
    best = np.argmin(distance, axis=1)
    rows = np.arange(len(points))
    return candidates[rows, best] + fraction[rows, best]


def align_paths(
    time: NDArray[np.float64],
    path: NDArray[np.float64],
    reference_time: NDArray[np.float64],
    reference_path: NDArray[np.float64],
) -> tuple[NDArray[np.float64], float]:
    """Reference times (n,) matching each sample of ``path`` (one phase), and the mean matched distance."""
    n, m = len(path), len(reference_path)
    if n == 0:
        return np.zeros(0), 0.0
    if m == 1:
        return np.full(n, reference_time[0]), float(np.linalg.norm(path - reference_path[0], axis=1).mean())
    mine = _resampled(n, MAX_DTW_POINTS)
    theirs = _resampled(m, MAX_DTW_POINTS)
    rows, cols, _ = dtw_path(path[mine], reference_path[theirs])
    # every sample's DTW seed: the reference sample matched to its nearest resampled neighbour
    seed_of_resampled = np.zeros(len(mine), dtype=np.int64)
    np.maximum.at(seed_of_resampled, rows, theirs[cols])
    seeds = np.interp(np.arange(n), mine, seed_of_resampled).round().astype(np.int64)
    window = max(4, int(np.ceil(m / len(theirs))) * 2, int(np.ceil(2 * m / n)) + 2)
    position = _project(path, reference_path, np.minimum(seeds, m - 2), window)
    # DTW pins a phase's first and last samples to the reference's; search their whole phase instead
    ends = np.unique([0, n - 1])
    position[ends] = _project(path[ends], reference_path, np.minimum(seeds[ends], m - 2), m)
    position = np.maximum.accumulate(position)  # time never runs backwards
    matched = np.interp(position, np.arange(m), reference_time)
    nearest = np.column_stack([np.interp(position, np.arange(m), reference_path[:, k]) for k in range(3)])
    return matched, float(np.linalg.norm(path - nearest, axis=1).mean())


def align_sessions(session: SessionStreams, reference: SessionStreams) -> Alignment:
    """Align ``session`` to ``reference`` phase by phase on the needle-tip path (tool path if no tip)."""
    for streams in (session, reference):
        if streams.needle_state is None:
            raise MetricsError(f"session {streams.session_id!r} has no needle state; phases cannot be found")
    mine = phase_starts(session.needle_state, session.time)
    theirs = phase_starts(reference.needle_state, reference.time)
    path = session.tip_position if session.tip_position is not None else session.tool_position
    reference_path = reference.tip_position if reference.tip_position is not None else reference.tool_position
    matched = np.full(session.time.size, np.nan)
    costs, weights = [], []
    for k in range(len(PHASES)):
        start, stop = mine[k], _next_bound(mine, k)
        if not np.isfinite(start):
            continue
        last = not np.isfinite(mine[k + 1 : -1]).any()  # no later phase: this one runs to the end
        inside = (session.time >= start) & ((session.time <= stop) if last else (session.time < stop))
        if not inside.any():
            continue
        reference_start = theirs[k] if np.isfinite(theirs[k]) else _last_reached(theirs, k)
        reference_stop = _next_bound(theirs, k)
        theirs_inside = (reference.time >= reference_start) & (reference.time <= reference_stop)
        if not theirs_inside.any():
            theirs_inside = np.zeros(reference.time.size, dtype=bool)
            theirs_inside[
                np.searchsorted(reference.time, reference_start).clip(0, reference.time.size - 1)
            ] = True
        times, cost = align_paths(
            session.time[inside],
            path[inside],
            reference.time[theirs_inside],
            reference_path[theirs_inside],
        )
        matched[inside] = times
        costs.append(cost * inside.sum())
        weights.append(inside.sum())
    if np.isnan(matched).any():
        raise MetricsError(f"session {session.session_id!r}: samples outside every phase (time not sorted?)")
    matched = np.maximum.accumulate(matched)
    return Alignment(session.time, matched, mine, theirs, float(np.sum(costs) / max(np.sum(weights), 1)))


def _next_bound(bounds: NDArray[np.float64], k: int) -> float:
    """End of phase k: the start of the next phase that was reached, else the end of the session."""
    later = bounds[k + 1 : -1]
    reached = later[np.isfinite(later)]
    return float(reached[0]) if reached.size else float(bounds[-1])


def _last_reached(bounds: NDArray[np.float64], k: int) -> float:
    earlier = bounds[: k + 1]
    return float(earlier[np.isfinite(earlier)][-1])


def decimated(streams: SessionStreams, rate_hz: float = 100.0) -> SessionStreams:
    """The time base, tool and tip paths and needle state at about ``rate_hz`` (every k-th sample and
    the last), enough to align sessions for display (10 ms at 100 Hz) at a fraction of the cost."""
    step = max(1, int(streams.sample_rate // rate_hz))
    keep = np.unique(np.r_[np.arange(0, streams.time.size, step), streams.time.size - 1])
    tip, state = streams.tip_position, streams.needle_state
    return SessionStreams(
        streams.session_id,
        streams.time[keep],
        streams.tool_position[keep],
        participant_id=streams.participant_id,
        label=streams.label,
        tip_position=None if tip is None else tip[keep],
        needle_state=None if state is None else state[keep],
    )
