"""A device's workspace mapped onto the task's scene: anchored at the start pose, 1:1 along the view's
axes, mirrored for a left hand, forces sent back into the device's frame."""

import numpy as np
import pytest

from sim.devices.base import DeviceIdentity, DeviceLimits, DeviceSample
from sim.devices.workspace import WorkspaceMapping, view_axes
from sim.needle import Pose, rotation_about

START = Pose(np.array([0.005, 0.001, 0.004]), rotation_about([0.2, 1.0, 0.3], 0.6))
VIEW = view_axes((0.02, 0.0, 0.03), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0))


class Hand:
    """A device whose pose the test sets: the reading at time t is ``poses[t]``; forces are kept."""

    identity, limits = DeviceIdentity("test", "hand"), DeviceLimits(3.0, 100.0)

    def __init__(self, poses):
        self.poses, self.forces = poses, []

    def read(self, time):
        position, rotation = self.poses[time]
        return DeviceSample(time, np.array(position), rotation, np.array([0.01, 0.0, 0.0]), 3)

    def write_force(self, force):
        self.forces.append(force)

    def close(self):
        pass


def test_the_first_reading_is_the_start_and_moves_follow_the_view_one_to_one():
    at_rest = rotation_about([1.0, 0.0, 0.0], 0.3)
    hand = Hand(
        {
            0.0: ([0.1, 0.2, 0.3], at_rest),
            1.0: ([0.102, 0.2, 0.301], rotation_about([0, 1, 0], 0.2) @ at_rest),
        }
    )
    mapped = WorkspaceMapping(hand, START, VIEW)
    first, later = mapped.read(0.0), mapped.read(1.0)
    np.testing.assert_allclose(first.position, START.position, atol=1e-15)
    np.testing.assert_allclose(first.rotation, START.rotation, atol=1e-12)
    # 2 mm to the device's right and 1 mm towards the user: the screen's right and out of the screen
    np.testing.assert_allclose(
        later.position - START.position, 0.002 * VIEW[:, 0] + 0.001 * VIEW[:, 2], atol=1e-12
    )
    # the hand's turn about its own up axis is a turn about the screen's up axis
    np.testing.assert_allclose(later.rotation @ START.rotation.T, rotation_about(VIEW[:, 1], 0.2), atol=1e-12)
    np.testing.assert_allclose(later.velocity, 0.01 * VIEW[:, 0], atol=1e-15)
    assert later.pressed(0) and later.pressed(1)
    mapped.write_force(VIEW[:, 0])  # a force to the screen's right is to the device's right
    np.testing.assert_allclose(hand.forces[-1], [1.0, 0.0, 0.0], atol=1e-12)


def test_a_left_hand_is_mirrored_across_the_screens_vertical_plane():
    rest = np.eye(3)
    hand = Hand({0.0: ([0.0, 0.0, 0.0], rest), 1.0: ([-0.003, 0.001, 0.0], rotation_about([0, 0, 1], 0.4))})
    mapped = WorkspaceMapping(hand, START, VIEW, mirror=True)
    mapped.read(0.0)
    later = mapped.read(1.0)
    # the left hand moving left moves the holder right; up stays up
    np.testing.assert_allclose(
        later.position - START.position, 0.003 * VIEW[:, 0] + 0.001 * VIEW[:, 1], atol=1e-12
    )
    turn = later.rotation @ START.rotation.T
    assert np.linalg.det(turn) == pytest.approx(1.0)  # still a rotation
    np.testing.assert_allclose(turn, rotation_about(VIEW[:, 2], -0.4), atol=1e-12)  # turned the other way
    mapped.write_force(VIEW[:, 0])
    np.testing.assert_allclose(hand.forces[-1], [-1.0, 0.0, 0.0], atol=1e-12)
