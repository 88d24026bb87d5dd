"""The compiled ring producer (recorder/_ring.c) against a plain-Python model of the ring."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from recorder._ring import RingProducer

WIDTH, HEAD, TAIL, DROPPED, FIRST, LAST = 5, 0, 1, 2, 3, 4


def ring_of(capacity):
    cells = np.zeros(capacity * WIDTH + 8)
    ring = cells[: capacity * WIDTH].reshape(capacity, WIDTH)
    end = capacity * WIDTH
    producer = RingProducer(
        cells, ring, WIDTH, capacity, end + HEAD, end + TAIL, end + DROPPED, end + FIRST, end + LAST
    )
    return cells, ring, cells[end:], producer


def as_kind(row, kind):
    if kind == "numpy":
        return row.copy()
    if kind == "memoryview":
        return memoryview(row.copy())
    if kind == "list":
        return row.tolist()
    if kind == "float32":
        return row.astype(np.float32)
    return np.repeat(row[:, None], 2, axis=1)[:, 0]  # strided


operations = st.lists(
    st.one_of(
        st.tuples(st.just("record"), st.sampled_from(["numpy", "memoryview", "list", "float32", "strided"])),
        st.tuples(st.just("consume"), st.integers(0, 9)),
    ),
    max_size=80,
)


@settings(max_examples=300, deadline=None)
@given(capacity=st.integers(1, 9), steps=operations)
def test_the_compiled_ring_matches_a_plain_model(capacity, steps):
    """Rows land in order in slot head % capacity, a full ring refuses and counts the drop with its
    time range, a consumer's tail frees room again; every row kind numpy converts is stored exactly."""
    cells, ring, counters, producer = ring_of(capacity)
    queued: list[np.ndarray] = []  # the model: rows written and not yet consumed
    dropped_times: list[float] = []
    written = 0
    for index, (action, arg) in enumerate(steps):
        if action == "record":
            row = np.array([index * 1e-3, index, -index, 0.5 * index, math.pi])
            if arg == "float32":
                row = row.astype(np.float32).astype(np.float64)
            kept = producer.record(as_kind(row, arg))
            assert kept == (len(queued) < capacity)
            if kept:
                np.testing.assert_array_equal(ring[written % capacity], row)
                queued.append(row)
                written += 1
            else:
                dropped_times.append(row[0])
        else:  # the writer thread's side: consume some rows, as flush() does
            taken = min(arg, len(queued))
            del queued[:taken]
            counters[TAIL] += taken
        assert counters[HEAD] == written
        assert counters[DROPPED] == len(dropped_times)
        if dropped_times:
            assert (counters[FIRST], counters[LAST]) == (dropped_times[0], dropped_times[-1])
    tail = int(counters[TAIL])
    for k, row in enumerate(queued):
        np.testing.assert_array_equal(ring[(tail + k) % capacity], row)


def test_a_wrong_length_row_is_refused_and_not_published():
    cells, ring, counters, producer = ring_of(4)
    for wrong in (np.zeros(WIDTH + 1), memoryview(np.zeros(WIDTH - 1)), [1.0, 2.0]):
        with pytest.raises(ValueError):
            producer.record(wrong)
    assert counters[HEAD] == 0
    with pytest.raises(ValueError):
        producer.record("not a row")
    assert counters[HEAD] == 0


def test_bad_layouts_are_refused_with_their_names():
    cells = np.zeros(4 * WIDTH + 8)
    ring = cells[: 4 * WIDTH].reshape(4, WIDTH)
    end = 4 * WIDTH
    with pytest.raises(ValueError, match="tail cell 3 is not among the counter cells"):
        RingProducer(cells, ring, WIDTH, 4, end, 3, end + 2, end + 3, end + 4)
    with pytest.raises(ValueError, match="last_dropped cell 28 is not among the counter cells"):
        RingProducer(cells, ring, WIDTH, 4, end, end + 1, end + 2, end + 3, end + 8)
    with pytest.raises(TypeError, match="must be float64"):
        RingProducer(cells.astype(np.float32), ring, WIDTH, 4, end, end + 1, end + 2, end + 3, end + 4)
    with pytest.raises(ValueError, match="must be positive"):
        RingProducer(cells, ring, 0, 4, end, end + 1, end + 2, end + 3, end + 4)
    with pytest.raises(ValueError, match="not C-contiguous"):
        strided = np.zeros(2 * (4 * WIDTH + 8))[::2]
        RingProducer(strided, ring, WIDTH, 4, end, end + 1, end + 2, end + 3, end + 4)
