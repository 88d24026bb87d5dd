"""Motion analysis on sampled 3-D paths: smoothing, speed, movements, smoothness.

All functions take time (s) and positions (m) as arrays and return SI values.
Smoothing is a zero-phase 4th-order Butterworth low-pass (``filtfilt``), the usual
choice in motor-control studies, so peaks do not shift in time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from itertools import pairwise

import numpy as np
from numpy.typing import NDArray

from metrics.errors import MetricsError

SMOOTHING_CUTOFF_HZ = 6.0
"""Low-pass cutoff for speed and jerk: hand movements carry little above ~6 Hz (tremor sits at 8-12 Hz)."""


def resample_uniform(
    time: NDArray[np.float64], values: NDArray[np.float64], rate: float | None = None
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Linear resampling onto a uniform grid at ``rate`` Hz (default: the median rate).

    The grid runs from the first sample to the last one it can reach, the last included even
    when rounding puts it a hair beyond (a rate of 99.99999999999991 keeps its 100th sample).
    """
    if rate is None:
        rate = 1.0 / float(np.median(np.diff(time)))
    steps = (time[-1] - time[0]) * rate
    n = max(2, int(math.floor(steps + 1e-6)) + 1)
    grid = time[0] + np.arange(n) / rate
    grid[-1] = min(grid[-1], time[-1])  # a grid point a rounding error past the end is the end
    if values.ndim == 1:
        return grid, np.interp(grid, time, values)
    return grid, np.column_stack([np.interp(grid, time, values[:, k]) for k in range(values.shape[1])])


def smooth(
    values: NDArray[np.float64], rate: float, cutoff_hz: float = SMOOTHING_CUTOFF_HZ
) -> NDArray[np.float64]:
    """Zero-phase low-pass along axis 0; returns the input when the signal is too short to filter."""
    if cutoff_hz >= rate / 2:
        return values
    from scipy import signal  # deferred: importing scipy.signal costs every command about 0.7 s

    sos = signal.butter(4, cutoff_hz, fs=rate, output="sos")
    padlen = 3 * (2 * len(sos) + 1)
    if values.shape[0] <= padlen:
        return values
    return signal.sosfiltfilt(sos, values, axis=0)


ANTI_ALIAS_FRACTION = 0.4
"""Before decimating to a rate r, the path is low-passed at no more than 0.4 r (80 % of the new Nyquist)."""


def path_length(position: NDArray[np.float64]) -> float:
    """Sum of straight segments between consecutive samples (m)."""
    if position.shape[0] < 2:
        return 0.0
    return float(np.sum(np.linalg.norm(np.diff(position, axis=0), axis=1)))


def velocity(time: NDArray[np.float64], position: NDArray[np.float64]) -> NDArray[np.float64]:
    """(n, 3) velocity by second-order finite differences (m/s)."""
    return np.gradient(position, time, axis=0)


@dataclass(frozen=True)
class UniformMotion:
    """A path resampled to a uniform rate and smoothed: the basis of the speed-based metrics."""

    rate: float
    time: NDArray[np.float64]
    position: NDArray[np.float64]
    speed: NDArray[np.float64]

    @classmethod
    def of(
        cls,
        time: NDArray[np.float64],
        position: NDArray[np.float64],
        rate: float | None = None,
        cutoff_hz: float = SMOOTHING_CUTOFF_HZ,
    ) -> UniformMotion:
        """Resample to the source's own (median) rate, low-pass there, then decimate to ``rate``.

        The low-pass runs before any decimation, at ``cutoff_hz`` or the anti-alias limit
        (:data:`ANTI_ALIAS_FRACTION` of the new rate), whichever is lower: a 99 Hz vibration
        sampled at 1 kHz does not fold into a 100 Hz path as slow motion.
        """
        grid, uniform = resample_uniform(time, position)
        source_rate = 1.0 / (grid[1] - grid[0])
        target = source_rate if rate is None or rate >= source_rate * (1 - 1e-9) else float(rate)
        cut = cutoff_hz if target == source_rate else min(cutoff_hz, ANTI_ALIAS_FRACTION * target)
        smoothed = smooth(uniform, source_rate, cut)
        if target != source_rate:
            coarse, smoothed = resample_uniform(grid, smoothed, target)
            grid = coarse
        speed = np.linalg.norm(np.gradient(smoothed, 1.0 / target, axis=0), axis=1)
        return cls(target, grid, smoothed, speed)


@dataclass(frozen=True)
class Movements:
    """Submovements of the speed profile.

    A *movement* is a stretch with speed above :data:`MOVEMENT_SPEED` lasting at least
    :data:`MIN_MOVEMENT_DURATION`; inside it, each speed peak standing at least
    :data:`MIN_PEAK_PROMINENCE` above the valleys around it is a submovement (one when
    none does, e.g. at constant speed). ``starts``/``ends``: each submovement's bounds,
    at the valleys between peaks and, at a movement's edges, where the speed stops
    falling below the threshold (a reach is taken from rest to rest).
    """

    peaks: NDArray[np.int64]
    starts: NDArray[np.int64]
    ends: NDArray[np.int64]

    @property
    def count(self) -> int:
        return int(self.peaks.size)


MOVEMENT_SPEED = 0.002
"""A movement is where the smoothed tool speed exceeds 2 mm/s (still hand and sensor noise stay below)."""
MIN_MOVEMENT_DURATION = 0.1
"""... for at least 0.1 s (a human submovement lasts >= ~150 ms)."""
MIN_PEAK_PROMINENCE = 0.002
"""A speed peak is its own submovement when it rises >= 2 mm/s above the valleys on both sides ..."""
LOCAL_PROMINENCE_FRACTION = 0.1
"""... and >= 10 % of its own movement's top speed (never a share of the session's fastest peak)."""


def _above(mask: NDArray[np.bool_]) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1


def find_movements(
    motion: UniformMotion,
    speed_threshold: float = MOVEMENT_SPEED,
    min_duration: float = MIN_MOVEMENT_DURATION,
    min_prominence: float = MIN_PEAK_PROMINENCE,
) -> Movements:
    """Movement segmentation by absolute thresholds (see :class:`Movements`; docs/metrics.md)."""
    from scipy.signal import find_peaks  # deferred: see smooth()

    speed = motion.speed
    peaks, starts, ends = [], [], []
    for first, last in zip(*_above(speed > speed_threshold), strict=True):
        if (last - first + 1) / motion.rate < min_duration:
            continue
        while first > 0 and speed[first - 1] < speed[first]:
            first -= 1  # out to rest (or the valley before the next movement)
        while last < speed.size - 1 and speed[last + 1] < speed[last]:
            last += 1
        inside = speed[first : last + 1]
        # a peak of its own: >= 2 mm/s and >= 10 % of this movement's top speed above its valleys
        # (the low-pass's ringing beside a fast reach is not a submovement)
        prominence = max(min_prominence, LOCAL_PROMINENCE_FRACTION * float(inside.max()))
        found, _ = find_peaks(inside, prominence=prominence)
        if found.size == 0:
            found = np.array([int(np.argmax(inside))])
        found = found + first
        bounds = [first]
        for left, right in pairwise(found):
            bounds.append(left + int(np.argmin(speed[left : right + 1])))
        bounds.append(last)
        peaks.extend(found)
        starts.extend(bounds[:-1])
        ends.extend(bounds[1:])
    as_int = lambda v: np.asarray(v, dtype=np.int64)  # noqa: E731
    return Movements(as_int(peaks), as_int(starts), as_int(ends))


def moving_path_length(motion: UniformMotion, movements: Movements) -> float:
    """Length travelled within movements (m): jitter of a still hand or sensor noise adds nothing."""
    return float(
        sum(
            path_length(motion.position[a : b + 1])
            for a, b in zip(movements.starts, movements.ends, strict=True)
        )
    )


def economy_of_motion(motion: UniformMotion, movements: Movements) -> float:
    """Straight-line displacement over path length, summed over movements: 1 = every movement straight."""
    if movements.count == 0:
        return math.nan
    travelled = 0.0
    direct = 0.0
    for start, end in zip(movements.starts, movements.ends, strict=True):
        segment = motion.position[start : end + 1]
        travelled += path_length(segment)
        direct += float(np.linalg.norm(segment[-1] - segment[0]))
    return direct / travelled if travelled > 0 else math.nan


LDLJ_CUTOFF_HZ = 20.0
"""Jerk is taken from the path low-passed at 20 Hz (where the source rate allows): the 6 Hz speed filter
would cut a 1 s minimum-jerk reach's LDLJ by 0.12. LDLJ stays sensitive to measurement noise above the
hand's band; SPARC is the noise-robust smoothness measure."""
SPLINE_BELOW_HZ = 200.0
"""Below 200 Hz jerk comes from a quintic interpolating spline (evaluated at 1 kHz), not finite
differences: at 30 Hz, three nested central differences smear a 1 s reach's jerk. It passes the
samples' own noise on: LDLJ at 30 Hz is only as good as the path it is given."""


def _jerk_integral(position: NDArray[np.float64], rate: float) -> tuple[float, float, float]:
    """(duration, peak speed, integral of |jerk|^2 dt) of one sampled path segment."""
    duration = (position.shape[0] - 1) / rate
    if rate < SPLINE_BELOW_HZ and position.shape[0] >= 6:
        from scipy.interpolate import make_interp_spline

        t = np.arange(position.shape[0]) / rate
        spline = make_interp_spline(t, position, k=5)  # all three axes in one banded solve
        fine = np.linspace(0.0, t[-1], max(2, int(round(t[-1] * 5.0 * SPLINE_BELOW_HZ)) + 1))
        dt = fine[1] - fine[0]
        speed = np.linalg.norm(spline.derivative(1)(fine), axis=1)
        jerk = spline.derivative(3)(fine)
    else:
        dt = 1.0 / rate
        speed = np.linalg.norm(np.gradient(position, dt, axis=0), axis=1)
        jerk = position
        for _ in range(3):
            jerk = np.gradient(jerk, dt, axis=0)
    return duration, float(speed.max()), float(np.trapezoid(np.sum(jerk * jerk, axis=1), dx=dt))


def log_dimensionless_jerk(motion: UniformMotion, segments: Movements | None = None) -> float:
    """LDLJ = -ln((T³ / v_peak²) ∫ |jerk|² dt) (Balasubramanian et al. 2015), per movement.

    ``segments``: the movements (index bounds into ``motion``); the result is the median of
    their LDLJs, so a long session of smooth reaches is not scored as one jerky movement
    (whole-session LDLJ is mostly ln T). Without segments the whole path is one movement.
    Higher (closer to zero) is smoother; a minimum-jerk reach scores -ln(204.8) = -5.32.
    """
    if segments is None:
        bounds = [(0, motion.position.shape[0] - 1)]
    else:
        bounds = list(zip(segments.starts, segments.ends, strict=True))
    values = []
    position = motion.position
    for start, end in bounds:
        # from the last sample at rest to the first one at rest again: samples of an exact pause
        # would make the interpolating spline ring across the reach's first jerk
        moved = np.flatnonzero(np.any(position[start : end + 1] != position[start], axis=1))
        if moved.size:
            start = start + max(0, int(moved[0]) - 1)
        still = np.flatnonzero(np.any(position[start : end + 1] != position[end], axis=1))
        if still.size:
            end = start + min(end - start, int(still[-1]) + 1)
        if end - start < 6:
            continue
        duration, peak, integral = _jerk_integral(motion.position[start : end + 1], motion.rate)
        if peak > 0 and duration > 0 and integral > 0:
            values.append(-math.log(duration**3 / peak**2 * integral))
    return float(np.median(values)) if values else math.nan


def on_grid(movements: Movements, source: UniformMotion, target: UniformMotion) -> Movements:
    """The same movements as index bounds into another motion of the same session (by time)."""

    def index(ix: NDArray[np.int64]) -> NDArray[np.int64]:
        found = np.searchsorted(target.time, source.time[ix] - 1e-12)
        return np.clip(found, 0, target.time.size - 1).astype(np.int64)

    return Movements(index(movements.peaks), index(movements.starts), index(movements.ends))


def spectral_arc_length(
    speed: NDArray[np.float64],
    rate: float,
    padlevel: int = 4,
    cutoff_hz: float = 10.0,
    threshold: float = 0.05,
) -> float:
    """SPARC: arc length of the normalised speed spectrum up to an adaptive cutoff (Balasubramanian 2015).

    The spectrum is zero-padded to 2^(ceil(log2 n) + padlevel) points; the cutoff is
    the last frequency below ``cutoff_hz`` where the magnitude is above ``threshold``.
    Returns a negative number; closer to zero is smoother.
    """
    n = speed.size
    if n < 4 or not np.any(speed > 0):
        return math.nan
    nfft = int(2 ** (math.ceil(math.log2(n)) + padlevel))
    frequency = np.arange(nfft // 2 + 1) * rate / nfft
    magnitude = np.abs(np.fft.rfft(speed, nfft))
    magnitude = magnitude / magnitude[0]
    inside = frequency <= cutoff_hz
    frequency, magnitude = frequency[inside], magnitude[inside]
    above = np.flatnonzero(magnitude >= threshold)
    last = int(above[-1]) if above.size else 0
    frequency, magnitude = frequency[: last + 1], magnitude[: last + 1]
    if frequency.size < 2:
        return math.nan
    df = np.diff(frequency) / frequency[-1]
    dm = np.diff(magnitude)
    return -float(np.sum(np.sqrt(df * df + dm * dm)))


IDLE_SPEED = 0.001
"""Below 1 mm/s the hand counts as still (needle insertion itself runs at a few mm/s)."""
IDLE_MIN_DURATION = 0.25
"""Stillness shorter than 0.25 s is part of a movement, not idling."""


def idle_time(
    motion: UniformMotion, idle_speed: float = IDLE_SPEED, min_duration: float = IDLE_MIN_DURATION
) -> float:
    """Total time (s) in stretches of at least ``min_duration`` with speed below ``idle_speed``."""
    still = motion.speed < idle_speed
    if not still.any():
        return 0.0
    edges = np.diff(np.concatenate([[0], still.astype(np.int8), [0]]))
    starts = np.flatnonzero(edges == 1)
    ends = np.flatnonzero(edges == -1)
    lengths = (ends - starts) / motion.rate
    return float(lengths[lengths >= min_duration].sum())


def require_positions(position: NDArray[np.float64], what: str) -> None:
    if position.ndim != 2 or position.shape[1] != 3:
        raise MetricsError(f"{what} must be (n, 3) positions; got shape {position.shape}")
