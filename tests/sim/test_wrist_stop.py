"""The wrist's stop on a cramped approach (issue 46: a task that cannot be done square without
everting the edge): the held needle's tip cannot be turned back past the stop, only about the
holder's shaft, and the stop says so once per time it holds the wrist."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from sim.needle import Needle, Pose
from sim.needle.geometry import NeedleError
from sim.needle.reach import REARM_DEG, WRIST_RANGE_DEG, WristLimit, WristStop

NORMAL = np.array([0.0, 0.0, 1.0])  # the wall faces +z
BITE = np.array([1.0, 0.0, 0.0])  # the needle is driven towards +x
NEEDLE = Needle.curved()
SHORT_DEG = 7.0
_FULL = 2 * math.pi * 3 / 8
CENTRE = -0.004 * np.array([math.cos(_FULL / 3), math.sin(_FULL / 3), 0.0])
"""The default needle's circle centre in its own frame: the grip, a third of the arc from the swage,
is the frame's origin (sim.needle.geometry)."""


def centre_of(holder: Pose, grasp: Pose) -> np.ndarray:
    needle = holder.compose(grasp)
    return needle.position + needle.rotation @ CENTRE


def _holder_square_to_the_wall(extra_back_deg: float = 0.0) -> Pose:
    """A holder whose needle's tip points straight into the wall (-z) with its drive towards +x, turned
    back (against the drive) by ``extra_back_deg``; the needle's circle axis (holder z) is then -y."""
    # holder frame -> world: the tip direction (local) onto -z, the circle's axis (local z) onto -y
    tip_local = NEEDLE.tip_direction
    local = np.column_stack([tip_local, np.cross([0.0, 0.0, 1.0], tip_local), [0.0, 0.0, 1.0]])
    into, axis = np.array([0.0, 0.0, -1.0]), np.array([0.0, -1.0, 0.0])
    world = np.column_stack([into, np.cross(axis, into), axis])
    rotation = world @ local.T
    back = Rotation.from_rotvec(math.radians(-extra_back_deg) * np.array([0.0, -1.0, 0.0])).as_matrix()
    return Pose(np.array([0.001, 0.002, 0.003]), back @ rotation)


def _tip(pose: Pose) -> np.ndarray:
    return pose.rotation @ NEEDLE.tip_direction


def test_a_drive_about_the_shaft_moves_the_tip_towards_the_bite():
    """The frame the tests build is the simulator's: turning about the needle's axis drives it forward."""
    pose = _holder_square_to_the_wall()
    np.testing.assert_allclose(_tip(pose), [0.0, 0.0, -1.0], atol=1e-12)
    forward = Rotation.from_rotvec(0.1 * pose.rotation[:, 2]).as_matrix() @ pose.rotation
    assert (forward @ NEEDLE.tip_direction) @ BITE > 0


def test_a_square_entry_is_turned_forward_to_the_stop_about_the_jaws():
    stop = WristStop.short_of_square(NORMAL, BITE, SHORT_DEG)
    limit = WristLimit(stop, NEEDLE)
    holder = _holder_square_to_the_wall()
    held, events = limit.hold(0.0, holder, Pose.identity())
    # turned about the needle's own centre: it stays on its circle, the holder moves with it
    np.testing.assert_allclose(
        centre_of(held, Pose.identity()), centre_of(holder, Pose.identity()), atol=1e-15
    )
    assert np.linalg.norm(held.position - holder.position) == pytest.approx(
        2 * 0.004 * math.sin(math.radians(SHORT_DEG) / 2), rel=1e-9
    )
    np.testing.assert_allclose(held.rotation[:, 2], holder.rotation[:, 2], atol=1e-12)  # about the shaft
    tip = _tip(held)
    assert math.degrees(math.acos(-tip @ NORMAL)) == pytest.approx(SHORT_DEG, abs=1e-9)
    assert tip @ BITE > 0  # tipped towards the bite: a wall everted away from it is met square
    assert [e.kind for e in events] == ["wrist_stop"]
    assert events[0].detail == "the tip held 7.0 deg short of where the hand turned it"


def test_one_event_while_the_hand_trembles_at_the_stop_and_another_after_it_came_away():
    limit = WristLimit(WristStop.short_of_square(NORMAL, BITE, SHORT_DEG), NEEDLE)
    kinds = []
    for k, back in enumerate([0.0, -6.9, 0.0, -6.5, 0.0]):  # at the stop, then just inside it, ...
        kinds += [e.kind for e in limit.hold(k * 1e-3, _holder_square_to_the_wall(back), Pose.identity())[1]]
    assert kinds == ["wrist_stop"]
    limit.hold(0.01, _holder_square_to_the_wall(-SHORT_DEG - REARM_DEG - 0.5), Pose.identity())  # away
    _, events = limit.hold(0.02, _holder_square_to_the_wall(), Pose.identity())
    assert [e.kind for e in events] == ["wrist_stop"]


def test_inside_the_range_the_pose_is_the_hands():
    limit = WristLimit(WristStop.short_of_square(NORMAL, BITE, SHORT_DEG), NEEDLE)
    for forward in (SHORT_DEG, 30.0, 120.0, SHORT_DEG + WRIST_RANGE_DEG - 1.0):
        holder = _holder_square_to_the_wall(-forward)
        held, events = limit.hold(0.0, holder, Pose.identity())
        assert held is holder and not events


def test_past_the_range_the_wrist_turns_back_to_its_end():
    limit = WristLimit(WristStop.short_of_square(NORMAL, BITE, SHORT_DEG), NEEDLE)
    holder = _holder_square_to_the_wall(-(SHORT_DEG + WRIST_RANGE_DEG + 10.0))
    held, events = limit.hold(0.0, holder, Pose.identity())
    shaft = held.rotation[:, 2]
    assert math.degrees(limit.stop.turn_past(_tip(held), shaft)) == pytest.approx(WRIST_RANGE_DEG, abs=1e-9)
    assert not events  # the supination end is no stop of the approach's


@settings(max_examples=200, deadline=None)
@given(
    st.lists(st.floats(-1.0, 1.0), min_size=4, max_size=4).filter(lambda q: np.linalg.norm(q) > 0.1),
    st.lists(st.floats(-1.0, 1.0), min_size=4, max_size=4).filter(lambda q: np.linalg.norm(q) > 0.1),
)
def test_any_held_pose_ends_inside_the_range_turned_only_about_the_shaft(holder_q, grasp_q):
    stop = WristStop.short_of_square(NORMAL, BITE, SHORT_DEG)
    limit = WristLimit(stop, NEEDLE)
    holder = Pose(np.array([0.001, -0.002, 0.004]), Rotation.from_quat(holder_q).as_matrix())
    grasp = Pose(np.array([1e-4, 0.0, -2e-4]), Rotation.from_quat(grasp_q).as_matrix())
    held, _ = limit.hold(0.0, holder, grasp)
    needle = held.compose(grasp)
    shaft, tip = needle.rotation[:, 2], needle.rotation @ NEEDLE.tip_direction
    np.testing.assert_allclose(centre_of(held, grasp), centre_of(holder, grasp), atol=1e-15)
    np.testing.assert_allclose(shaft, holder.compose(grasp).rotation[:, 2], atol=1e-9)
    past = stop.turn_past(tip, shaft)
    if math.isnan(past):  # the shaft along the stop's direction: nothing to turn against
        assert held is holder
    else:
        assert -1e-9 <= past <= math.radians(WRIST_RANGE_DEG) + 1e-9
        assert np.allclose(held.rotation.T @ held.rotation, np.eye(3), atol=1e-9)


def test_a_stop_needs_a_direction_and_a_range():
    with pytest.raises(NeedleError, match="tip_limit"):
        WristStop(np.zeros(3))
    with pytest.raises(NeedleError, match="range_deg"):
        WristStop(np.array([0.0, 0.0, -1.0]), range_deg=360.0)
