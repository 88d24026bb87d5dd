"""Motion analysis on sampled 3-D paths: smoothing, speed, movements, smoothness.

All functions take time (s) and positions (m) as arrays and return SI values.
Smoothing is a zero-phase 4th-order Butterworth low-pass (``filtfilt``), the usual
choice in motor-control studies, so peaks do not shift in time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import signal

from metrics.streams import MetricsError

SMOOTHING_CUTOFF_HZ = 6.0
"""Low-pass cutoff for speed and jerk: hand movements carry little above ~6 Hz (tremor sits at 8-12 Hz)."""


def resample_uniform(
    time: NDArray[np.float64], values: NDArray[np.float64], rate: float | None = None
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Linear resampling onto a uniform grid at ``rate`` Hz (default: the median rate)."""
    if rate is None:
        rate = 1.0 / float(np.median(np.diff(time)))
    n = max(2, int(math.floor((time[-1] - time[0]) * rate)) + 1)
    grid = time[0] + np.arange(n) / rate
    if values.ndim == 1:
        return grid, np.interp(grid, time, values)
    return grid, np.column_stack([np.interp(grid, time, values[:, k]) for k in range(values.shape[1])])


def smooth(
    values: NDArray[np.float64], rate: float, cutoff_hz: float = SMOOTHING_CUTOFF_HZ
) -> NDArray[np.float64]:
    """Zero-phase low-pass along axis 0; returns the input when the signal is too short to filter."""
    if cutoff_hz >= rate / 2:
        return values
    sos = signal.butter(4, cutoff_hz, fs=rate, output="sos")
    padlen = 3 * (2 * len(sos) + 1)
    if values.shape[0] <= padlen:
        return values
    return signal.sosfiltfilt(sos, values, axis=0)


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
        grid, uniform = resample_uniform(time, position, rate)
        rate = 1.0 / (grid[1] - grid[0])
        smoothed = smooth(uniform, rate, cutoff_hz)
        speed = np.linalg.norm(np.gradient(smoothed, 1.0 / rate, axis=0), axis=1)
        return cls(rate, grid, smoothed, speed)


@dataclass(frozen=True)
class Movements:
    """Submovements found as peaks of the speed profile.

    peaks: sample indices of each movement's speed peak; starts/ends: where the
    speed first falls below ``onset_fraction`` of that peak on either side.
    """

    peaks: NDArray[np.int64]
    starts: NDArray[np.int64]
    ends: NDArray[np.int64]

    @property
    def count(self) -> int:
        return int(self.peaks.size)


MIN_PEAK_SPEED = 0.002
"""Speed peaks below 2 mm/s are not movements (sensor noise and drift)."""
PEAK_PROMINENCE_FRACTION = 0.2
"""A peak counts when it rises at least 20 % of the session's largest speed above the valleys around it."""
MIN_PEAK_SEPARATION = 0.1
"""Two peaks closer than 0.1 s are one movement (a human submovement lasts >= ~150 ms)."""


def find_movements(
    motion: UniformMotion,
    min_peak_speed: float = MIN_PEAK_SPEED,
    prominence_fraction: float = PEAK_PROMINENCE_FRACTION,
    min_separation: float = MIN_PEAK_SEPARATION,
    onset_fraction: float = 0.1,
) -> Movements:
    """Velocity-peak movement segmentation (thresholds above; all documented in docs/metrics.md)."""
    speed = motion.speed
    top = float(speed.max()) if speed.size else 0.0
    if top < min_peak_speed:
        empty = np.zeros(0, dtype=np.int64)
        return Movements(empty, empty, empty)
    peaks, _ = signal.find_peaks(
        speed,
        height=min_peak_speed,
        prominence=prominence_fraction * top,
        distance=max(1, int(round(min_separation * motion.rate))),
    )
    starts = np.empty_like(peaks)
    ends = np.empty_like(peaks)
    for k, peak in enumerate(peaks):
        level = onset_fraction * speed[peak]
        before = np.flatnonzero(speed[:peak] < level)
        after = np.flatnonzero(speed[peak:] < level)
        starts[k] = before[-1] if before.size else 0
        ends[k] = peak + after[0] if after.size else speed.size - 1
    return Movements(peaks.astype(np.int64), starts.astype(np.int64), ends.astype(np.int64))


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


def log_dimensionless_jerk(motion: UniformMotion) -> float:
    """LDLJ = -ln((T³ / v_peak²) ∫ |jerk|² dt), speed-normalised (Balasubramanian et al. 2015).

    Higher (closer to zero) is smoother; a minimum-jerk reach scores -ln(204.8) = -5.32.
    """
    dt = 1.0 / motion.rate
    peak = float(motion.speed.max())
    duration = motion.time[-1] - motion.time[0]
    if peak <= 0 or duration <= 0 or motion.position.shape[0] < 7:
        return math.nan
    jerk = motion.position
    for _ in range(3):
        jerk = np.gradient(jerk, dt, axis=0)
    integral = float(np.trapezoid(np.sum(jerk * jerk, axis=1), dx=dt))
    if integral <= 0:
        return math.nan
    return -math.log(duration**3 / peak**2 * integral)


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
