"""The compiled haptic force path (sim/runtime/_haptic.c) against the Python channels and safety
filter it replaces in the real-time haptic process: the same inputs give the same forces bit for bit,
the same holder slot, log rows and safety events, and the filter's state handed back."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sim.devices.base import DeviceLimits
from sim.needle import Pose
from sim.runtime.force_path import CompiledForcePath
from sim.runtime.safety import ForceSafety, SafetySettings
from sim.runtime.shared import Arena, SharedForceHistory, SharedHapticLog, SharedHolder
from sim.runtime.snapshots import HolderSnapshot

LIMITS = DeviceLimits(max_force=3.3, max_force_rate=400.0)


def channels(capacity: int, log_capacity: int):
    arena = Arena(
        SharedHolder.doubles() + SharedForceHistory.doubles(capacity) + SharedHapticLog.doubles(log_capacity)
    )
    return SharedHolder(arena), SharedForceHistory(arena, capacity), SharedHapticLog(arena, log_capacity)


def reference_tick(holder, forces, log, safety, delay, scale, now, position, rotation, velocity, grip):
    """Simulation.haptic_step's force path in Python (sim/runtime/simulation.py)."""
    holder.put(HolderSnapshot(now, Pose.unchecked(position, rotation), velocity, grip))
    target = forces.at(now - delay)
    if scale != 1.0:
        target = scale * target
    force = safety.filter(now, target, forces.latest_time)
    log.append(now, position, grip, force)
    return force


force_values = st.one_of(
    st.floats(-5.0, 5.0),  # beyond the 3.3 N rating: the clamp acts
    st.just(math.nan),
    st.just(math.inf),
)
operations = st.lists(
    st.one_of(
        st.tuples(st.just("push"), st.floats(0.0, 0.02), st.tuples(force_values, force_values, force_values)),
        st.tuples(
            st.just("tick"),
            st.floats(0.0, 0.08),  # gaps past the 50 ms stall timeout: the watchdog acts and recovers
            st.tuples(st.floats(-0.1, 0.1), st.floats(-0.1, 0.1), st.floats(-0.1, 0.1)),
            st.booleans(),
        ),
    ),
    min_size=1,
    max_size=120,
)


@settings(max_examples=150, deadline=None)
@given(
    operations=operations,
    delay=st.sampled_from([0.0, 0.002, 0.01]),
    scale=st.sampled_from([1.0, 0.5]),
    capacity=st.sampled_from([2, 5, 64]),
)
def test_the_compiled_force_path_equals_the_python_one_bit_for_bit(operations, delay, scale, capacity):
    log_capacity = 100  # fewer rows than ticks sometimes: a full log drops later ticks in both
    python_side, compiled_side = channels(capacity, log_capacity), channels(capacity, log_capacity)
    reference = ForceSafety(LIMITS, SafetySettings(), tick=1e-3)
    compiled_safety = ForceSafety(LIMITS, SafetySettings(), tick=1e-3)
    path = CompiledForcePath(*compiled_side, compiled_safety, delay, scale)
    rotation = np.eye(3)[[1, 2, 0]].T  # a transposed view: a device may hand one over
    fem_time = tick_time = 0.0
    for operation in operations:
        if operation[0] == "push":
            fem_time += operation[1]
            force = np.array(operation[2])
            python_side[1].push(fem_time, force)
            compiled_side[1].push(fem_time, force)
            continue
        _, gap, position, grip = operation
        tick_time += gap
        position, velocity = np.array(position), np.array(position) * 10.0
        expected = reference_tick(
            *python_side, reference, delay, scale, tick_time, position, rotation, velocity, grip
        )
        got = path.tick(tick_time, position, rotation, velocity, grip)
        assert got.tobytes() == expected.tobytes(), (got, expected)
        assert python_side[0].cells.tobytes() == compiled_side[0].cells.tobytes()  # the holder slot
    assert python_side[2].cells[0].tobytes() == compiled_side[2].cells[0].tobytes()  # the log rows
    assert python_side[2].count == compiled_side[2].count
    assert compiled_safety.events == reference.events
    path.hand_back()
    assert compiled_safety.state_cells()[:7].tobytes() == reference.state_cells()[:7].tobytes()
    stops = [compiled_safety.stop_sequence(tick_time, 1e-3), reference.stop_sequence(tick_time, 1e-3)]
    assert [[(t, f.tobytes()) for t, f in stop] for stop in stops[:1]] == [
        [(t, f.tobytes()) for t, f in stops[1]]
    ]  # the paced stop goes on from the handed-back state


def test_a_holder_read_back_is_the_pose_published():
    holder, forces, log = channels(8, 8)
    path = CompiledForcePath(holder, forces, log, ForceSafety(LIMITS), 0.0, 1.0)
    rotation = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    path.tick(0.25, np.array([0.01, 0.02, 0.03]), rotation, np.array([0.1, 0.0, 0.0]), True)
    snapshot = holder.get()
    assert snapshot.time == 0.25 and snapshot.grip is True
    np.testing.assert_array_equal(snapshot.pose.rotation, rotation)
    np.testing.assert_array_equal(snapshot.pose.position, [0.01, 0.02, 0.03])
    assert holder.cells[0] % 2 == 0  # the seqlock left consistent


def test_wrong_inputs_are_refused_with_their_name():
    holder, forces, log = channels(8, 8)
    path = CompiledForcePath(holder, forces, log, ForceSafety(LIMITS), 0.0, 1.0)
    with pytest.raises(ValueError, match="rotation must be 9 float64 values"):
        path.tick(0.0, np.zeros(3), np.eye(2), np.zeros(3), False)
    with pytest.raises(ValueError, match="position must be 3 float64 values"):
        path.tick(0.0, np.zeros(3, dtype=np.float32), np.eye(3), np.zeros(3), False)
    with pytest.raises(TypeError, match="takes 5 arguments"):
        path._kernel.tick(0.0)


def test_warming_reads_but_writes_nothing():
    holder, forces, log = channels(8, 8)
    safety = ForceSafety(LIMITS)
    path = CompiledForcePath(holder, forces, log, safety, 0.0, 1.0)
    forces.push(0.0, np.array([5.0, 0.0, 0.0]))  # clamped, rate-limited: the state moves every tick
    path.tick(0.001, np.zeros(3), np.eye(3), np.zeros(3), True)
    before = [a.copy() for a in (holder.cells, *log.cells, path.state, path.force)]
    path.warm(0.002)
    after = (holder.cells, *log.cells, path.state, path.force)
    assert all(np.array_equal(a, b, equal_nan=True) for a, b in zip(before, after, strict=True))
    assert len(safety.events) == 1  # the clamp, from the tick; warming reported nothing
