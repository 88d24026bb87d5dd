"""Motion metrics against analytic answers."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import integrate

from metrics import SessionStreams, metrics_of
from metrics.signals.kinematics import (
    UniformMotion,
    find_movements,
    idle_time,
    log_dimensionless_jerk,
    path_length,
    spectral_arc_length,
)


def minimum_jerk(t, duration, amplitude=1.0):
    s = np.clip(t / duration, 0, 1)
    return amplitude * (10 * s**3 - 15 * s**4 + 6 * s**5)


def test_path_length_of_a_helix():
    radius, pitch, turns = 0.02, 0.005, 3
    angle = np.linspace(0, 2 * np.pi * turns, 200_001)
    helix = np.column_stack([radius * np.cos(angle), radius * np.sin(angle), pitch * angle / (2 * np.pi)])
    exact = turns * math.hypot(2 * np.pi * radius, pitch)
    assert path_length(helix) == pytest.approx(exact, rel=1e-8)


@given(st.lists(st.tuples(*[st.floats(-1, 1)] * 3), min_size=2, max_size=30))
def test_path_length_is_at_least_the_chord(points):
    points = np.array(points)
    assert path_length(points) >= np.linalg.norm(points[-1] - points[0]) - 1e-12


def test_minimum_jerk_ldlj_is_known():
    """For a minimum-jerk reach, T^3/v_peak^2 * int jerk^2 = 720 / 1.875^2 = 204.8 (independent of T, A)."""
    rate, duration = 1000.0, 1.3
    t = np.arange(0, duration + 1e-12, 1 / rate)
    x = minimum_jerk(t, duration, 0.07)
    motion = UniformMotion.of(t, np.column_stack([x, 0 * x, 0 * x]), rate, cutoff_hz=rate)  # no smoothing
    assert log_dimensionless_jerk(motion) == pytest.approx(-math.log(204.8), abs=0.01)


def test_sparc_of_a_gaussian_speed_profile_matches_the_analytic_spectrum():
    """|V(f)| of a Gaussian speed bump is exp(-2 pi^2 sigma^2 f^2); its arc length is an integral."""
    rate, sigma = 200.0, 0.15
    t = np.arange(-3, 3, 1 / rate)
    speed = np.exp(-(t**2) / (2 * sigma**2))
    spectrum = lambda f: np.exp(-2 * np.pi**2 * sigma**2 * f**2)  # noqa: E731
    derivative = lambda f: -4 * np.pi**2 * sigma**2 * f * spectrum(f)  # noqa: E731
    cutoff = min(10.0, math.sqrt(-math.log(0.05) / (2 * np.pi**2 * sigma**2)))
    arc, _ = integrate.quad(lambda f: math.sqrt((1 / cutoff) ** 2 + derivative(f) ** 2), 0, cutoff)
    assert spectral_arc_length(speed, rate) == pytest.approx(-arc, rel=5e-3)


def test_sparc_and_ldlj_rank_a_jerky_movement_as_less_smooth():
    rate = 100.0
    t = np.arange(0, 2, 1 / rate)
    smooth = minimum_jerk(t, 2.0, 0.05)
    jerky = smooth + 0.002 * np.sin(2 * np.pi * 3 * t)
    a = UniformMotion.of(t, np.column_stack([smooth, 0 * t, 0 * t]), rate)
    b = UniformMotion.of(t, np.column_stack([jerky, 0 * t, 0 * t]), rate)
    assert spectral_arc_length(b.speed, rate) < spectral_arc_length(a.speed, rate)
    assert log_dimensionless_jerk(b) < log_dimensionless_jerk(a)


@pytest.mark.parametrize("count", [1, 2, 5])
def test_movement_count_on_constructed_speed_profiles(count):
    """``count`` minimum-jerk reaches separated by pauses, with the pauses' speed exactly zero."""
    rate, reach, pause = 100.0, 0.6, 0.4
    pieces, offset = [], 0.0
    for k in range(count):
        t = np.arange(0, reach, 1 / rate)
        amplitude = 0.02 * (1 + 0.5 * (k % 2))
        pieces.append(offset + minimum_jerk(t, reach, amplitude))
        offset = pieces[-1][-1]
        pieces.append(np.full(int(pause * rate), offset))
    x = np.concatenate(pieces)
    t = np.arange(x.size) / rate
    motion = UniformMotion.of(t, np.column_stack([x, 0 * x, 0 * x]), rate)
    assert find_movements(motion).count == count


def test_tremor_below_threshold_is_not_a_movement():
    rate = 100.0
    t = np.arange(0, 3, 1 / rate)
    x = minimum_jerk(t - 1, 0.8, 0.03) + 2e-6 * np.sin(2 * np.pi * 9 * t)
    motion = UniformMotion.of(t, np.column_stack([x, 0 * x, 0 * x]), rate)
    assert find_movements(motion).count == 1


def test_idle_time_counts_only_long_still_stretches():
    rate = 100.0
    speed_profile = np.r_[
        np.full(50, 0.01), np.zeros(100), np.full(50, 0.01), np.zeros(10), np.full(50, 0.01)
    ]
    x = np.cumsum(speed_profile) / rate
    t = np.arange(x.size) / rate
    motion = UniformMotion(rate, t, np.column_stack([x, 0 * x, 0 * x]), speed_profile)
    assert idle_time(motion) == pytest.approx(1.0)  # the 1 s pause; the 0.1 s one is too short


def test_metrics_of_a_table_without_optional_streams_are_nan_not_guessed():
    t = np.linspace(0, 4, 401)
    streams = SessionStreams("s", t, np.column_stack([minimum_jerk(t, 4, 0.05), 0 * t, 0 * t]))
    values = metrics_of(streams)
    assert values["task_time"] == pytest.approx(4.0)
    assert values["path_length"] == pytest.approx(0.05, rel=1e-5)  # the 6 Hz filtered path
    for name in ("peak_force", "entry_angle_error_deg", "high_stress_area", "peak_stretch", "attempts"):
        assert math.isnan(values[name]), name


@settings(max_examples=30, deadline=None)
@given(st.floats(0.01, 100), st.floats(-1, 1))
def test_smoothness_is_scale_invariant(scale, shift):
    rate = 100.0
    t = np.arange(0, 2, 1 / rate)
    x = minimum_jerk(t, 1.5, 0.05) + 0.001 * np.sin(2 * np.pi * 2 * t)
    base = UniformMotion.of(t, np.column_stack([x, 0 * t, 0 * t]), rate)
    scaled = UniformMotion.of(t, np.column_stack([scale * x + shift, 0 * t, 0 * t]), rate)
    assert log_dimensionless_jerk(scaled) == pytest.approx(log_dimensionless_jerk(base), abs=1e-6)
    assert spectral_arc_length(scaled.speed, rate) == pytest.approx(
        spectral_arc_length(base.speed, rate), abs=1e-9
    )
