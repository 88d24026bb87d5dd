"""The shared-memory channels against their in-process counterparts."""

import itertools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sim.runtime.logs import ForceHistory
from sim.runtime.shared import Arena, SharedEvents, SharedForceHistory

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


def test_the_compiled_tick_writes_the_holder_and_its_log_where_their_one_declaration_says():
    """Issue 48: the holder slot and a haptic log row are laid out once, by name
    (sim.runtime.snapshots.HOLDER_LAYOUT, HAPTIC_LOG_LAYOUT), and the compiled haptic tick
    (sim/runtime/_haptic.c) is given their places (it wrote at fixed offsets, which a test read out of
    the C source). Layouts declared in another order are written in that order; a field of the wrong
    width, or outside its slot, is refused with the field's name."""
    from sim.runtime._haptic import ForcePath
    from sim.runtime.force_path import HOLDER_FIELDS, LOG_FIELDS
    from sim.runtime.snapshots import HAPTIC_LOG_LAYOUT, HOLDER_LAYOUT, SlotLayout

    shuffled = SlotLayout(
        (("grip", 1), ("velocity", 3), ("seq", 1), ("rotation", 9), ("time", 1), ("position", 3))
    )
    log_layout = SlotLayout((("force", 3), ("spare", 2), ("grip", 1), ("position", 3), ("time", 1)))
    holder = np.zeros(shuffled.size + 2)
    ring, counter = np.zeros((8, 4)), np.zeros(1)
    log, count = np.zeros((4, log_layout.size)), np.zeros(1)
    state, out = np.zeros(16), np.zeros(3)
    parameters = (0.05, 0.1, 3.0, 100.0, 1e-3, 0.0, 1.0)
    cells = (holder, ring, counter, log, count, state, out, parameters)
    row = (log_layout.size, log_layout.spans(LOG_FIELDS))
    kernel = ForcePath(*cells, shuffled.spans(HOLDER_FIELDS), row)
    rotation = np.arange(9.0).reshape(3, 3)
    kernel.tick(0.25, np.array([0.01, 0.02, 0.03]), rotation, np.array([0.4, 0.5, 0.6]), True)
    assert (
        holder[shuffled["seq"]] == 2.0
        and holder[shuffled["time"]] == 0.25
        and holder[shuffled["grip"]] == 1.0
    )
    np.testing.assert_array_equal(holder[shuffled["position"]], [0.01, 0.02, 0.03])
    np.testing.assert_array_equal(holder[shuffled["rotation"]], rotation.ravel())
    np.testing.assert_array_equal(holder[shuffled["velocity"]], [0.4, 0.5, 0.6])
    assert holder[-2:].tolist() == [0.0, 0.0]  # nothing written past the layout
    logged = log[0]
    assert count[0] == 1 and logged[log_layout["time"]] == 0.25 and logged[log_layout["grip"]] == 1.0
    np.testing.assert_array_equal(logged[log_layout["position"]], [0.01, 0.02, 0.03])
    np.testing.assert_array_equal(logged[log_layout["force"]], out)
    assert logged[log_layout["spare"]].tolist() == [0.0, 0.0] and not log[1:].any()

    standard = (
        HOLDER_LAYOUT.spans(HOLDER_FIELDS),
        (HAPTIC_LOG_LAYOUT.size, HAPTIC_LOG_LAYOUT.spans(LOG_FIELDS)),
    )
    narrow = SlotLayout(
        (("seq", 1), ("time", 1), ("position", 2), ("rotation", 9), ("velocity", 3), ("grip", 1))
    )
    with pytest.raises(ValueError, match="the holder's position must be 3 cells"):
        ForcePath(np.zeros(narrow.size), *cells[1:], narrow.spans(HOLDER_FIELDS), standard[1])
    with pytest.raises(ValueError, match="the holder's grip must be 1 cells inside its 17"):
        ForcePath(np.zeros(17), *cells[1:], *standard)  # one cell short
    with pytest.raises(ValueError, match="the log row's force must be 3 cells inside its 7"):
        ForcePath(np.zeros(18), *cells[1:], standard[0], (7, HAPTIC_LOG_LAYOUT.spans(LOG_FIELDS)))


def test_a_snapshot_read_from_shared_memory_is_the_one_written():
    """The holder and FEM slots round-trip every field by name (as the haptic process reads them)."""
    from sim.needle import Pose
    from sim.runtime.shared import SharedFem, SharedHolder
    from sim.runtime.snapshots import FEM_LAYOUT, FemSnapshot, HolderSnapshot

    arena = Arena(SharedHolder.doubles() + SharedFem.doubles())
    holder, fem = SharedHolder(arena), SharedFem(arena, for_display=True)
    rotation = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    pose = Pose(np.array([1.0, 2.0, 3.0]), rotation)
    holder.put(HolderSnapshot(0.25, pose, np.array([4.0, 5.0, 6.0]), True))
    fem.put(
        FemSnapshot(
            time=0.5,
            needle_force=np.array([0.1, 0.2, 0.3]),
            needle_vertices=np.array([[7.0, 8.0, 9.0], [7.5, 8.0, 9.0], [8.0, 8.5, 9.0]]),
            state="pierced",
            contact_nodes=np.zeros(0, dtype=np.int64),
            reaction_forces=np.zeros((0, 3)),
            tip_speed=0.004,
            tip_tangent=np.array([0.0, 0.0, 1.0]),
            contact_triangle=42,
            barycentric=(0.2, 0.3, 0.5),
            local_stress=5e5,
            stretch=1.1,
            tip_velocity=np.array([1e-3, 2e-3, 3e-3]),
            grasp_force=np.array([0.0, 0.2, 0.1]),
            grasp_displacement=np.array([0.0, 0.0, 3e-4]),
            wrist_at_stop=True,
            holder_time=0.497,
            jaws=(np.array([1e-3, 2e-3, 3e-3]), True),
        )
    )
    fem._owner = -1  # read as the haptic process does, from the slot
    back, seen = holder.get(), fem.get()
    assert back.time == 0.25 and back.grip and np.array_equal(back.pose.rotation, rotation)
    assert np.array_equal(back.pose.position, [1, 2, 3]) and np.array_equal(back.velocity, [4, 5, 6])
    assert (seen.time, seen.state, seen.contact_triangle, seen.tip_speed) == (0.5, "pierced", 42, 0.004)
    assert seen.barycentric == (0.2, 0.3, 0.5) and (seen.local_stress, seen.stretch) == (5e5, 1.1)
    assert np.array_equal(seen.needle_force, [0.1, 0.2, 0.3])
    assert np.array_equal(seen.needle_vertices, [[7, 8, 9], [7.5, 8, 9], [8, 8.5, 9]])  # the display's
    assert np.array_equal(seen.tip_tangent, [0, 0, 1])
    assert (
        seen.holder_time == 0.497
        and seen.jaws[1] is True
        and np.array_equal(seen.jaws[0], [1e-3, 2e-3, 3e-3])
    )
    assert np.array_equal(seen.tip_velocity, [1e-3, 2e-3, 3e-3])
    assert np.array_equal(seen.grasp_force, [0, 0.2, 0.1])
    assert np.array_equal(seen.grasp_displacement, [0, 0, 3e-4])
    assert seen.wrist_at_stop is True
    assert FEM_LAYOUT.size == SharedFem.doubles() == 29 + 1 + 3 * 64 + 1 + 4


def test_a_one_handed_snapshot_reads_back_with_no_grasp():
    from sim.runtime.shared import SharedFem
    from sim.runtime.snapshots import FemSnapshot

    fem = SharedFem(Arena(SharedFem.doubles()))
    fem.put(
        FemSnapshot(0.1, np.zeros(3), np.zeros((1, 3)), "free", np.zeros(0, dtype=np.int64), np.zeros((0, 3)))
    )
    fem._owner = -1
    seen = fem.get()
    assert seen.grasp_force is None and seen.grasp_displacement is None and seen.jaws is None
    assert math.isnan(seen.holder_time)  # shared only for a display process
    long = np.zeros((65, 3))  # a needle of more vertices than the slot holds: its tip
    long[0] = [1.0, 2.0, 3.0]
    fem.put(FemSnapshot(0.2, np.zeros(3), long, "free", np.zeros(0, dtype=np.int64), np.zeros((0, 3))))
    assert np.array_equal(fem.get().needle_vertices, [[1, 2, 3]])


def test_the_display_gets_both_hands_loads_and_the_jaws():
    """The graphics slot carries the forceps' jaws and the needle's and the grasp's loads as one set
    (a node both load carries the sum), which the display process solves for the wall it draws."""
    from sim.forceps.grasp import with_grasp
    from sim.runtime.shared import SharedGraphics
    from sim.runtime.snapshots import GraphicsSnapshot

    graphics = SharedGraphics(Arena(SharedGraphics.doubles()))
    needle = (np.array([3, 7]), np.array([[0.0, 0.0, -0.1], [0.0, 0.0, -0.2]]), 0.5)
    loads = with_grasp(needle, np.array([7, 9]), np.array([[0.0, 0.05, 0.0], [0.0, 0.05, 0.0]]))
    assert loads[0].tolist() == [3, 7, 9] and loads[2] == 0.5
    np.testing.assert_array_equal(loads[1], [[0, 0, -0.1], [0, 0.05, -0.2], [0, 0.05, 0]])
    jaws = (np.array([1e-3, 2e-3, 3e-3]), True)
    graphics.put(GraphicsSnapshot(0.2, np.zeros((4, 3)), "contact", None, None, 0.19, loads, jaws))
    seen = graphics.get()
    assert seen.loads[0].tolist() == [3, 7, 9] and np.array_equal(seen.loads[1], loads[1])
    assert np.array_equal(seen.jaws[0], jaws[0]) and seen.jaws[1] is True
    graphics.put(GraphicsSnapshot(0.3, np.zeros((4, 3)), "free", None, None, 0.29, None, None))
    seen = graphics.get()
    assert seen.jaws is None and seen.loads is None
    alone = with_grasp(None, np.array([9]), np.array([[0.0, 0.05, 0.0]]))
    assert alone[0].tolist() == [9] and np.isnan(alone[2])


@settings(max_examples=60, deadline=None)
@given(details=st.lists(st.text(max_size=140), min_size=1, max_size=6))
def test_the_haptic_process_events_keep_their_detail_text(details):
    """The haptic process's events crossed to the parent as (time, code) only: a clamped force was
    recorded without its "1200 mN clamped to the rated 880 mN". Now the detail crosses too, cut at a
    character within its 96 bytes (never a broken character)."""
    events = SharedEvents(Arena(SharedEvents.doubles(capacity=8)), capacity=8)
    for k, detail in enumerate(details):
        events.add(0.5 * k, "force_clamped", detail)
    read = events.read()
    assert [(when, kind) for when, kind, _ in read] == [
        (0.5 * k, "force_clamped") for k in range(len(details))
    ]
    for (_, _, got), sent in zip(read, details, strict=True):
        encoded = sent.encode()
        assert len(got.encode()) <= SharedEvents.DETAIL_BYTES
        assert encoded.startswith(got.encode())
        assert got == sent or len(encoded) > SharedEvents.DETAIL_BYTES
    assert events.read(len(details) - 1) == read[-1:]


def test_a_clamp_message_reads_back_whole():
    events = SharedEvents(Arena(SharedEvents.doubles(capacity=2)), capacity=2)
    events.add(1.25, "force_clamped", "1200 mN clamped to the rated 880 mN")
    events.add(2.0, "watchdog")
    events.add(3.0, "watchdog")  # over capacity: dropped, never written past the block
    assert events.read() == [
        (1.25, "force_clamped", "1200 mN clamped to the rated 880 mN"),
        (2.0, "watchdog", ""),
    ]


def test_the_window_draws_the_instruments_of_the_newest_fem_step_read_from_another_process():
    """Motion to photon (issue 42): the live window draws the wall as the graphics frame left it and
    the needle and forceps where the newest FEM step has them, read through shared memory as the
    display process reads them (the whole needle, not its tip), with that step's device sample time;
    a FEM step older than the graphics frame (or none yet) leaves the frame's own."""
    from sim.needle import Needle, Pose
    from sim.render import RenderFrame
    from sim.runtime.display import instruments_now
    from sim.runtime.shared import SharedFem
    from sim.runtime.snapshots import FemSnapshot, GraphicsSnapshot

    needle = Needle.curved()
    then = needle.world_vertices(Pose(np.zeros(3), np.eye(3)))
    now = needle.world_vertices(Pose(np.array([1e-3, 0.0, 0.0]), np.eye(3)))
    graphics = GraphicsSnapshot(1.0, then, "free", None, holder_time=0.99, jaws=(np.zeros(3), False))
    frame = RenderFrame(np.zeros((4, 3)), np.zeros(2), then, forceps=graphics.jaws)
    fem = SharedFem(Arena(SharedFem.doubles()), for_display=True)
    jaws = (np.array([0.0, 2e-3, 0.0]), True)
    fem.put(
        FemSnapshot(
            1.012, np.zeros(3), now, "free", np.zeros(0, dtype=np.int64), np.zeros((0, 3)), holder_time=1.011,
            jaws=jaws,
        )
    )  # fmt: skip
    fem._owner = -1  # the display process's view of the slot
    drawn, sample_time = instruments_now(frame, graphics, fem.get())
    assert np.array_equal(drawn.needle, now) and len(drawn.needle) == len(then) > 1
    assert drawn.forceps[1] is True and np.array_equal(drawn.forceps[0], jaws[0]) and sample_time == 1.011
    assert drawn.points is frame.points  # the wall as the graphics frame left it
    tip_only = fem.get()._replace(needle_vertices=now[:1])  # what the slot gives of a very long needle
    for stale in (None, fem.get()._replace(time=0.98), tip_only):
        kept, kept_time = instruments_now(frame, graphics, stale)
        assert kept is frame and kept_time == 0.99
