"""A camera-tracked tool path as the motion metrics read it: measured poses only, smoothed.

A camera measures the instrument 30-120 times a second with a fraction of a millimetre of noise per
frame; the haptic loop fills the ticks between frames by extrapolation and freezes the tool while
tracking is lost (:mod:`sim.tracking.channel`). Path length and smoothness computed from that raw
1 kHz stream would count the noise and the extrapolation's small corrections as movement. The motion
metrics therefore read a camera session's tool path as the bench-video importer reads a tracked
video: samples whose pose was predicted or held are left out and bridged by straight lines, and the
path is low-passed, zero-phase: at :data:`CAMERA_SMOOTHING_HZ` for a live camera session, at
:data:`TRACKED_SMOOTHING_HZ` for a bench video (one flat marker, whose poses are noisier).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from metrics.signals.kinematics import smooth

TRACKED_SMOOTHING_HZ = 3.0
"""Low-pass cut-off for a bench video's tracked path. At 30 frames/s a flat marker's pose noise (~0.5 mm
per frame at 30 cm) dominates above ~3 Hz, where deliberate suturing hand motion has little power; at
6 Hz the jerk-based smoothness (LDLJ) of a tracked bench path was 10 % off its ground truth, at 3 Hz 1.7 %."""
CAMERA_SMOOTHING_HZ = 4.0
"""Low-pass cut-off for a live camera session's tool path (a marker cube, corners on fitted edges,
0.1-0.5 mm per frame at 30 cm). A filmed scripted wall stitch played back through ``camera:FILE``
(``benchmarks/camera.py``) kept its path length within 0.5 % and SPARC within 0.3 % at 4 Hz, against
2.0 % and 5.9 % at 3 Hz and 1.8 % and 3.5 % at 6 Hz."""


def gap_lengths(found: NDArray[np.bool_], time: NDArray[np.float64]) -> NDArray[np.float64]:
    """Length (s) of each run of samples where ``found`` is False."""
    edges = np.diff(np.r_[0, (~found).astype(int), 0])
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    step = float(np.median(np.diff(time)))
    return (stops - starts) * step


def bridged(time: NDArray[np.float64], raw: NDArray[np.float64]) -> NDArray[np.float64]:
    """``raw`` (n, 3) with its NaN rows replaced by straight lines between the measured neighbours
    (held at the first and last measured value at the ends)."""
    found = np.isfinite(raw).all(axis=1)
    return np.column_stack([np.interp(time, time[found], raw[found, k]) for k in range(raw.shape[1])])


def tracked_path(
    time: NDArray[np.float64], raw: NDArray[np.float64], cutoff_hz: float = TRACKED_SMOOTHING_HZ
) -> NDArray[np.float64]:
    """The measured path (NaN rows: not measured) bridged and low-passed zero-phase at ``cutoff_hz``."""
    filled = bridged(time, raw)
    rate = 1.0 / float(np.median(np.diff(time)))
    return smooth(filled, rate, cutoff_hz)


def measured_path(
    time: NDArray[np.float64],
    values: NDArray[np.float64],
    labels: NDArray,
    cutoff_hz: float = CAMERA_SMOOTHING_HZ,
) -> NDArray[np.float64]:
    """A camera-tracked path as the metrics read it: the samples labelled measured (0) bridged and
    smoothed (:func:`tracked_path`); the path as recorded when fewer than four were measured."""
    measured = np.asarray(labels) == 0
    if measured.sum() < 4:
        return values
    return tracked_path(time, np.where(measured[:, None], values, np.nan), cutoff_hz)
