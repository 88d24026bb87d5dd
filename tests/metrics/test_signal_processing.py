"""Signal processing sound at 30 Hz and at 1 kHz (issue 20, seen 7): each case failed on the old code."""

from __future__ import annotations

import math

import numpy as np
import pytest

from metrics import SessionStreams, metrics_of
from metrics.signals.kinematics import (
    UniformMotion,
    economy_of_motion,
    find_movements,
    idle_time,
    resample_uniform,
)

RATES = (30.0, 100.0, 1000.0)
MINIMUM_JERK_LDLJ = -math.log(720 / 1.875**2)  # -5.32


def minimum_jerk(t, duration, amplitude):
    s = np.clip(t / duration, 0.0, 1.0)
    return amplitude * (10 * s**3 - 15 * s**4 + 6 * s**5)


def _line(x):
    return np.column_stack([x, np.zeros_like(x), np.zeros_like(x)])


def test_a_vibration_above_the_band_is_not_motion():
    """Seen: a still tool with a 0.5 mm, 99 Hz vibration at 1 kHz gave 19 movements and 0 s idle."""
    rate = 1000.0
    t = np.arange(0, 10, 1 / rate)
    x = 0.0005 * np.sin(2 * np.pi * 99 * t)
    motion = UniformMotion.of(t, _line(x), 100.0)
    assert find_movements(motion).count == 0
    assert idle_time(motion) == pytest.approx(10.0, abs=0.02)


def test_resampling_keeps_the_last_sample():
    """Seen: at a rate of 99.99999999999991 the last sample was dropped."""
    rate = 99.99999999999991
    t = np.arange(100) / 100.0
    grid, values = resample_uniform(t, t.copy(), rate)
    assert grid.size == 100 and grid[-1] == t[-1] and values[-1] == t[-1]


def _reaches(rate, specs, pause=0.5):
    """Minimum-jerk reaches (duration, amplitude) along x, each followed by a pause at rest."""
    pieces, offset = [], 0.0
    for duration, amplitude in specs:
        t = np.arange(0, duration, 1 / rate)
        pieces.append(offset + minimum_jerk(t, duration, amplitude))
        offset += amplitude
        pieces.append(np.full(int(pause * rate), offset))
    x = np.concatenate([np.zeros(int(pause * rate)), *pieces])
    return np.arange(x.size) / rate, x


@pytest.mark.parametrize("rate", RATES)
def test_five_slow_reaches_and_one_fast_are_six_movements(rate):
    """Seen: five slow reaches plus one fast one counted as 1 (prominence relative to the fastest peak)."""
    t, x = _reaches(rate, [(1.0, 0.01)] * 5 + [(0.4, 0.12)])
    motion = UniformMotion.of(t, _line(x), min(100.0, rate))
    assert find_movements(motion).count == 6


@pytest.mark.parametrize("rate", RATES)
def test_constant_speed_is_one_straight_movement(rate):
    """Seen: constant speed gave 0 movements and economy NaN."""
    t = np.arange(0, 4, 1 / rate)
    motion = UniformMotion.of(t, _line(0.01 * t), min(100.0, rate))
    movements = find_movements(motion)
    assert movements.count == 1
    assert economy_of_motion(motion, movements) == pytest.approx(1.0, abs=1e-9)


@pytest.mark.parametrize("rate", RATES)
def test_sensor_noise_does_not_add_path_length(rate):
    """Seen: 0.05 mm white noise made a 0.10 m path 0.104 / 0.113 / 0.271 m at 30 Hz / 100 Hz / 1 kHz."""
    rng = np.random.default_rng(int(rate))
    t, x = _reaches(rate, [(1.2, 0.025)] * 4, pause=0.6)
    clean = _line(x)
    noisy = clean + rng.normal(0.0, 5e-5, clean.shape)
    values = metrics_of(SessionStreams("noisy", t, noisy))
    assert values["path_length"] == pytest.approx(0.10, rel=0.02)


@pytest.mark.parametrize("rate", RATES)
def test_minimum_jerk_reach_has_the_known_ldlj(rate):
    """Seen: -5.06 at 30 Hz for a 1 s minimum-jerk reach (analytic -5.32)."""
    t, x = _reaches(rate, [(1.0, 0.05)])
    values = metrics_of(SessionStreams("reach", t, _line(x)))
    assert values["log_dimensionless_jerk"] == pytest.approx(MINIMUM_JERK_LDLJ, abs=0.05)


@pytest.mark.parametrize("rate", (30.0, 1000.0))
def test_ldlj_is_not_task_time_in_disguise(rate):
    """Seen: whole-session LDLJ tracked ln T (r = -0.93 on JIGSAWS). The same reach five times, with
    pauses, is as smooth as once."""
    once = metrics_of(SessionStreams("once", *_line_session(rate, 1)))
    five = metrics_of(SessionStreams("five", *_line_session(rate, 5)))
    assert five["task_time"] > 3 * once["task_time"]
    assert five["log_dimensionless_jerk"] == pytest.approx(once["log_dimensionless_jerk"], abs=0.02)


def _line_session(rate, count):
    t, x = _reaches(rate, [(1.0, 0.05)] * count)
    return t, _line(x)
