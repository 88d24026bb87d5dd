"""Alignment on constructed paths: a time-warped copy maps back to the original's time exactly."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from metrics import SessionStreams
from metrics.signals.alignment import PHASES, align_sessions, dtw_path, phase_starts


def expert_path(t):
    """A stitch-like tip path (m): approach from above, press, turn through the wall, come out."""
    return np.column_stack(
        [
            0.01 * np.sin(0.7 * t) + 0.002 * t,
            0.004 * np.cos(1.3 * t),
            0.006 - 0.0015 * t + 0.001 * np.sin(2.1 * t),
        ]
    )


def expert_state(t):
    return np.select([t < 1.0, t < 1.6, t < 3.2], [0, 1, 2], 3).astype(np.int8)


def session(name, times, positions, state):
    return SessionStreams(name, times, positions, tip_position=positions, needle_state=state)


def expert(rate=100.0, duration=4.0):
    t = np.arange(0.0, duration + 1e-12, 1.0 / rate)
    return session("expert", t, expert_path(t), expert_state(t))


def warped_copy(reference: SessionStreams, speed_a: float, speed_b: float, rate: float):
    """The reference replayed at a varying speed: reference time s(t) = speed_a t + speed_b t^2, sampled at
    ``rate``; positions on the reference's own polyline (linear interpolation between its samples)."""
    end = reference.time[-1]
    # s(stop) = end, solved without the cancellation of the textbook formula for small speed_b
    stop = 2 * end / (speed_a + np.sqrt(speed_a**2 + 4 * speed_b * end))
    t = np.arange(0.0, stop, 1.0 / rate)
    s = speed_a * t + speed_b * t**2
    positions = np.column_stack(
        [np.interp(s, reference.time, reference.tip_position[:, k]) for k in range(3)]
    )
    # the state follows the reference's: a phase starts at the first sample at or after its start
    state = expert_state(s)
    return session("trainee", t, positions, state), s


def test_dtw_on_a_repeated_sample():
    a = np.array([[0.0], [1.0], [2.0], [3.0]])
    b = np.array([[0.0], [1.0], [1.0], [2.0], [3.0]])
    rows, cols, cost = dtw_path(a, b)
    assert cost == 0.0
    assert list(zip(rows.tolist(), cols.tolist(), strict=True)) == [(0, 0), (1, 1), (1, 2), (2, 3), (3, 4)]


def test_dtw_matches_a_brute_force_recurrence():
    rng = np.random.default_rng(3)
    a, b = rng.normal(size=(17, 3)), rng.normal(size=(23, 3))
    _, _, cost = dtw_path(a, b)
    c = np.linalg.norm(a[:, None] - b[None], axis=-1)
    d = np.full((18, 24), np.inf)
    d[0, 0] = 0.0
    for i in range(1, 18):
        for j in range(1, 24):
            d[i, j] = c[i - 1, j - 1] + min(d[i - 1, j - 1], d[i - 1, j], d[i, j - 1])
    assert cost == pytest.approx(d[-1, -1], rel=1e-12)


def test_a_time_stretched_copy_aligns_exactly():
    reference = expert()
    copy, truth = warped_copy(reference, 0.5, 0.0, 100.0)  # half speed: twice as long
    alignment = align_sessions(copy, reference)
    np.testing.assert_allclose(alignment.reference_times, truth, atol=1e-9)
    assert alignment.cost < 1e-12


@settings(max_examples=25, deadline=None)
@given(speed_a=st.floats(0.3, 2.5), speed_b=st.floats(0.0, 0.4), rate=st.sampled_from([60.0, 100.0, 250.0]))
def test_any_monotone_speed_change_maps_back_to_the_original_time(speed_a, speed_b, rate):
    reference = expert()
    copy, truth = warped_copy(reference, speed_a, speed_b, rate)
    alignment = align_sessions(copy, reference)
    np.testing.assert_allclose(alignment.reference_times, truth, atol=1e-7)
    assert np.all(np.diff(alignment.reference_times) >= 0)


def test_phases_are_matched_to_phases():
    reference = expert()
    copy, _ = warped_copy(reference, 0.8, 0.1, 100.0)
    alignment = align_sessions(copy, reference)
    for k in range(1, len(PHASES)):
        start = alignment.phase_bounds[k]
        mapped = alignment.reference_time_at(start)
        # the copy's first sample of a phase maps into the reference's same phase, within a sample
        assert (
            alignment.reference_phase_bounds[k] - 1e-9 <= mapped <= alignment.reference_phase_bounds[k] + 0.01
        )


def test_phase_starts_when_a_session_never_pierces():
    t = np.arange(0, 2.0, 0.01)
    state = np.where(t < 1.0, 0, 1)
    bounds = phase_starts(state, t)
    assert bounds[0] == 0.0 and bounds[1] == pytest.approx(1.0)
    assert np.isnan(bounds[2]) and np.isnan(bounds[3]) and bounds[4] == pytest.approx(1.99)


def test_a_session_that_stops_early_still_aligns_monotonically():
    reference = expert()
    t = np.arange(0.0, 1.4, 0.01)  # approach and part of the contact, never pierces
    copy = session("short", t, expert_path(t), expert_state(t))
    alignment = align_sessions(copy, reference)
    np.testing.assert_allclose(alignment.reference_times, t, atol=1e-9)
