"""Keyboard and mouse as the needle holder: the hand's arithmetic, the channel, the device's easing."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sim.devices.base import DeviceError
from sim.devices.mouse import MouseDevice, MouseHand, MouseMapping, PoseChannel, needle_circle
from sim.needle import Needle, Pose, rotation_about


def start() -> Pose:
    return Pose(np.array([0.01, 0.002, 0.005]), rotation_about([0.3, 1.0, 0.2], 0.7))


def test_the_wrist_turns_the_needle_about_its_own_centre_and_the_tip_goes_forward():
    needle = Needle.curved()
    hand = MouseHand(start())
    vertices = needle.world_vertices(hand.pose)
    centre, axis = needle_circle(vertices)
    hand.turn(0.5, +1, vertices)  # half a second at 60 deg/s: 30 deg
    turned = needle.world_vertices(hand.pose)
    # every point of the needle keeps its distance to the centre (it turns on its own circle)...
    np.testing.assert_allclose(
        np.linalg.norm(turned - centre, axis=1), np.linalg.norm(vertices - centre, axis=1), rtol=1e-12
    )
    # ...by 30 deg, and the tip moves the way it points
    moved = turned[0] - vertices[0]
    assert np.dot(moved, vertices[0] - vertices[1]) > 0
    cosine = np.dot(vertices[0] - centre, turned[0] - centre) / np.linalg.norm(vertices[0] - centre) ** 2
    assert math.degrees(math.acos(cosine)) == pytest.approx(30.0, rel=1e-9)
    back = MouseHand(hand.pose)
    back.turn(0.5, -1, turned)
    np.testing.assert_allclose(back.pose.position, start().position, atol=1e-15)


def test_a_left_hand_swaps_the_turn_keys_and_bad_mappings_are_refused():
    right, left = MouseMapping(), MouseMapping(handedness="left")
    assert [right.turn_direction(k) for k in ("d", "Right", "a", "Left", "x")] == [1, 1, -1, -1, 0]
    assert [left.turn_direction(k) for k in ("d", "Right", "a", "Left", "x")] == [-1, -1, 1, 1, 0]
    with pytest.raises(DeviceError, match="handedness must be 'right' or 'left'; got 'both'"):
        MouseMapping(handedness="both")
    with pytest.raises(DeviceError, match="turn_rate_deg_s"):
        MouseMapping(turn_rate_deg_s=0)


def test_wheel_and_drag_move_the_holder_by_what_they_say():
    hand = MouseHand(start())
    hand.wheel(4, np.array([0.0, 0.0, -2.0]))
    hand.move(np.array([0.001, 0.0, 0.0]))
    np.testing.assert_allclose(hand.pose.position - start().position, [0.001, 0.0, -4 * 2.5e-4], atol=1e-15)
    np.testing.assert_array_equal(hand.pose.rotation, start().rotation)
    hand.toggle_grip()
    assert hand.grip is False


def test_the_channel_carries_the_newest_pose_and_grip():
    channel = PoseChannel()
    assert channel.get() is None
    channel.put(0.5, start(), False)
    channel.put(0.6, start(), True)
    seq, time, pose, grip = channel.get()
    assert seq == 4 and time == 0.6 and grip is True
    np.testing.assert_array_equal(pose.position, start().position)
    np.testing.assert_array_equal(pose.rotation, start().rotation)


@settings(max_examples=40, deadline=None)
@given(
    step=st.tuples(*(st.floats(-0.002, 0.002) for _ in range(3))),
    angle=st.floats(-0.3, 0.3),
)
def test_the_device_eases_each_new_pose_in_over_one_frame_without_a_jump(step, angle):
    """A pose published at display rate (30 Hz) reaches the haptic loop spread over 33 ms: at 1 kHz no
    tick moves the holder more than 1/33 of the step (plus rounding), and the end is the pose sent."""
    channel = PoseChannel()
    device = MouseDevice(start(), channel)
    target = Pose.unchecked(
        start().position + np.array(step), rotation_about([0, 0, 1], angle) @ start().rotation
    )
    previous = device.read(0.0).position
    channel.put(0.0, target, True)
    largest = 0.0
    for k in range(1, 60):
        sample = device.read(k * 1e-3)
        largest = max(largest, float(np.linalg.norm(sample.position - previous)))
        previous = sample.position
        assert np.allclose(sample.rotation @ sample.rotation.T, np.eye(3), atol=1e-12)
    assert largest <= np.linalg.norm(step) / 33.3 * 1.0001 + 1e-15
    np.testing.assert_allclose(previous, target.position, atol=1e-15)
    np.testing.assert_allclose(device.read(0.1).rotation, target.rotation, atol=1e-12)
    assert device.read(0.1).pressed(0)


def test_turning_back_stops_at_the_wrist_stop_and_a_forward_turn_moves_at_once():
    """Seen at the station on inside-edge: A held past the stop wound the hand on while the needle
    stayed, so D then turned nothing until it had unwound as much."""
    from sim.needle.reach import WristStop

    needle = Needle.curved()
    hand = MouseHand(start())
    vertices = needle.world_vertices(hand.pose)
    centre, axis = needle_circle(vertices)
    tip = np.cross(axis, vertices[0] - centre)
    tip /= np.linalg.norm(tip)
    # a stop 10 deg back from where the tip points now, as seen about the needle's own axis
    stop = WristStop(rotation_about(axis, math.radians(-10.0)) @ tip)
    hand = MouseHand(start(), stop=stop)
    for _ in range(30):  # A held for a second at 60 deg/s, a display frame at a time
        hand.turn(1 / 30, -1, needle.world_vertices(hand.pose))
    shown = needle.world_vertices(hand.pose)
    at = np.cross(axis, shown[0] - centre)
    assert stop.turn_past(at / np.linalg.norm(at), axis) == pytest.approx(0.0, abs=1e-9)  # at the stop
    before = hand.pose.position.copy()
    hand.turn(1 / 30, +1, shown)  # D: the needle moves on the first frame
    assert np.linalg.norm(hand.pose.position - before) > 1e-5
    loose = MouseHand(start(), stop=stop, grip=False)  # an open hand turns the jaws, not the needle
    loose.turn(1.0, -1, vertices)
    assert not np.allclose(loose.pose.rotation, start().rotation)
