"""The shared-memory channels against their in-process counterparts."""

import itertools

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from sim.runtime.shared import Arena, SharedForceHistory
from sim.runtime.simulation import ForceHistory

CAPACITY = 16


@settings(max_examples=300, deadline=None)
@given(
    steps=st.lists(st.floats(1e-4, 5e-3), min_size=0, max_size=3 * CAPACITY),
    forces=st.lists(st.tuples(*[st.floats(-5.0, 5.0)] * 3), min_size=3 * CAPACITY, max_size=3 * CAPACITY),
    repeats=st.sets(st.integers(0, 3 * CAPACITY)),
    queries=st.lists(st.floats(-0.01, 0.2), min_size=1, max_size=20),
)
def test_the_shared_force_history_interpolates_as_the_in_process_one(steps, forces, repeats, queries):
    """Bit for bit over the outputs the ring still holds (capacity - 1), wrap-around included;
    repeated times (two outputs at one instant) and times outside the history included."""
    shared = SharedForceHistory(Arena(CAPACITY * 4 + 1), capacity=CAPACITY)
    plain = ForceHistory(capacity=1000)
    times = np.cumsum(steps)
    pushed = []
    for k, when in enumerate(times):
        when = times[k - 1] if k in repeats and k > 0 else when
        force = np.array(forces[k])
        shared.push(float(when), force)
        pushed.append((float(when), force))
    for when, force in pushed[-(CAPACITY - 1) :]:  # what the ring still holds
        plain.push(when, force)
    held = pushed[-(CAPACITY - 1) :]
    middles = [0.5 * (a[0] + b[0]) for a, b in itertools.pairwise(held)]
    for query in queries + [t for t, _ in held] + middles:
        np.testing.assert_array_equal(shared.at(query), plain.at(query))
    assert shared.latest_time == plain.latest_time


def test_an_empty_history_gives_zero_force():
    shared = SharedForceHistory(Arena(CAPACITY * 4 + 1), capacity=CAPACITY)
    np.testing.assert_array_equal(shared.at(1.0), np.zeros(3))
    assert shared.latest_time is None


def test_a_long_force_delay_reaches_back_past_64_outputs():
    """0.2 s of delay at a 1 kHz FEM is 200 outputs back: the ring's whole depth is searched."""
    shared = SharedForceHistory(Arena(512 * 4 + 1))
    for k in range(1000):
        shared.push(k * 1e-3, np.array([k, 0.0, 0.0]))
    np.testing.assert_allclose(shared.at(0.999 - 0.2), [799.0, 0.0, 0.0])
