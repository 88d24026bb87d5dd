"""Devices through the same code paths the live hardware uses, fed bytes and samples we construct."""

import math
import struct

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sim.devices import DeviceError, DeviceLostError, ReplayDevice, ScriptedDevice, SuturingPass
from sim.devices.scripted import (
    SuturingPassParameters,
    matrix_quaternion,
    quaternion_matrix,
    sequence_of_passes,
)
from sim.devices.spacemouse import SpaceMouse, SpaceMouseDecoder
from sim.devices.usb_discovery import identify, scan_usb
from sim.fem import Material, TissueModel
from sim.mesh import box_mesh
from sim.needle import Needle, NeedleError, Pose, TurnAbout, rotation_about
from sim.needle.forces import NeedleForces
from sim.needle.interaction import NeedleInteraction

PAPER = NeedleForces.paper()  # these tests drive the paper's soft tissue with its needle rule


def old_reports(translation, rotation, buttons=0):
    """Reports of an older SpaceMouse (SpaceNavigator): ids 1 and 2 with 3 axes each, id 3 buttons."""
    return [
        bytes([1]) + struct.pack("<3h", *translation),
        bytes([2]) + struct.pack("<3h", *rotation),
        bytes([3]) + buttons.to_bytes(2, "little"),
    ]


def new_report(translation, rotation):
    """The combined 13-byte report of newer models (SpaceMouse Wireless, Compact)."""
    return bytes([1]) + struct.pack("<6h", *translation, *rotation)


def test_decoder_reads_both_report_formats_and_buttons():
    old = SpaceMouseDecoder()
    for report in old_reports((350, -175, 0), (0, 35, -350), buttons=0b10):
        state = old.feed(report)
    np.testing.assert_allclose(state.translation, [1.0, -0.5, 0.0])
    np.testing.assert_allclose(state.rotation, [0.0, 0.1, -1.0])
    assert state.buttons == 2
    new = SpaceMouseDecoder()
    state = new.feed(new_report((350, -175, 0), (0, 35, -350)))
    np.testing.assert_allclose(state.translation, [1.0, -0.5, 0.0])
    np.testing.assert_allclose(state.rotation, [0.0, 0.1, -1.0])
    assert len(new_report((0, 0, 0), (0, 0, 0))) == 13
    with pytest.raises(DeviceError, match="SpaceMouse report 2 too short: 3 bytes"):
        new.feed(bytes([2, 0, 1]))
    assert new.feed(bytes([23, 100])).buttons == 0  # battery report: ignored


class RecordedHid:
    """An open HID handle replaying recorded reports, then failing like an unplugged device."""

    def __init__(self, frames, unplug_after=None):
        self.frames = list(frames)
        self.reads = 0
        self.unplug_after = unplug_after

    def read(self, size):
        self.reads += 1
        if self.unplug_after is not None and self.reads > self.unplug_after:
            raise OSError("read error: device disconnected")
        return list(self.frames.pop(0)) if self.frames else []

    def close(self):
        pass


def test_live_spacemouse_path_integrates_a_pose_and_reports_unplug():
    frames = [new_report((350, 0, 0), (0, 0, 0))]
    mouse = SpaceMouse(source=RecordedHid(frames, unplug_after=3), origin=np.zeros(3))
    first = mouse.read(0.0)
    assert first.position.tolist() == [0, 0, 0]
    later = mouse.read(0.5)  # full deflection in x for 0.5 s at 20 mm/s
    np.testing.assert_allclose(later.position, [0.01, 0, 0])
    np.testing.assert_allclose(later.velocity, [0.02, 0, 0])
    with pytest.raises(DeviceLostError, match="stopped answering"):
        mouse.read(0.6)


def test_rotation_axis_integrates():
    mouse = SpaceMouse(source=RecordedHid([new_report((0, 0, 0), (0, 0, 350))]))
    mouse.read(0.0)
    sample = mouse.read(0.5)  # 1 rad/s about z for 0.5 s
    np.testing.assert_allclose(sample.rotation, rotation_about([0, 0, 1], 0.5), atol=1e-12)


def test_usb_table_and_scan():
    assert identify(0x0301, 0x2988).product == "3D Systems Touch (USB)"
    assert identify(0x1451, 0x0402).product.startswith("Force Dimension")
    assert identify(0x256F, 0xC635).driver == "spacemouse (hidapi)"
    assert identify(0x1234, 0x5678) is None
    assert isinstance(scan_usb(), list)  # the real libusb backend answers (no known devices here)


def test_openhaptics_names_what_is_missing():
    from sessions.cli.base import remedy_in_words
    from sim.devices.openhaptics import OpenHapticsDevice

    with pytest.raises(
        DeviceError, match=r"OpenHaptics runtime .*Use the scripted or SpaceMouse device"
    ) as refused:
        OpenHapticsDevice()
    assert remedy_in_words(refused.value) == "; pass --device scripted or spacemouse"  # the CLI's words


def test_quaternions_round_trip():
    for axis, angle in (([0, 0, 1], 0.3), ([1, 1, 0], 2.0), ([0, 1, 0], math.pi)):
        rotation = rotation_about(axis, angle)
        np.testing.assert_allclose(quaternion_matrix(matrix_quaternion(rotation)), rotation, atol=1e-12)


def samples():
    times = np.linspace(0, 1, 11)
    positions = np.column_stack([times * 0.01, np.zeros(11), np.zeros(11)])
    quaternions = np.array([matrix_quaternion(rotation_about([0, 0, 1], 0.5 * t)) for t in times])
    grips = (times < 0.55).astype(float)
    return times, positions, quaternions, grips


def test_replay_device_interpolates_samples():
    device = ReplayDevice(*samples(), session="s-1")
    sample = device.read(0.25)
    np.testing.assert_allclose(sample.position, [0.0025, 0, 0], atol=1e-15)
    np.testing.assert_allclose(sample.velocity, [0.01, 0, 0], rtol=1e-9)
    np.testing.assert_allclose(sample.rotation, rotation_about([0, 0, 1], 0.125), atol=1e-3)
    assert sample.buttons == 1 and device.read(0.9).buttons == 0
    assert "replay" in str(device.identity)
    device.write_force(np.array([0.1, 0, 0]))
    assert device.forces.array.shape == (1, 4)


def test_scripted_device_from_csv_and_parquet(tmp_path):
    times, positions, quaternions, grips = samples()
    columns = {
        "time": times,
        "x": positions[:, 0],
        "y": positions[:, 1],
        "z": positions[:, 2],
        "qw": quaternions[:, 0],
        "qx": quaternions[:, 1],
        "qy": quaternions[:, 2],
        "qz": quaternions[:, 3],
        "grip": grips,
    }
    csv = tmp_path / "pass.csv"
    np.savetxt(
        csv, np.column_stack(list(columns.values())), delimiter=",", header=",".join(columns), comments=""
    )
    parquet = tmp_path / "pass.parquet"
    pq.write_table(pa.table(columns), parquet)
    for path in (csv, parquet):
        device = ScriptedDevice.from_file(path)
        np.testing.assert_allclose(device.read(0.5).position, [0.005, 0, 0], atol=1e-12)
    bad = tmp_path / "bad.csv"
    bad.write_text("time,x,y\n0,0,0\n")
    with pytest.raises(DeviceError, match=r"bad.csv lacks column\(s\) z, qw, qx, qy, qz"):
        ScriptedDevice.from_file(bad)
    with pytest.raises(DeviceError, match="does not exist"):
        ScriptedDevice.from_file(tmp_path / "missing.csv")
    backwards = times.copy()
    backwards[4] = backwards[3]
    with pytest.raises(DeviceError, match=r"sample 4 \(0.3 s\) is not after sample 3"):
        ReplayDevice(backwards, positions, quaternions)


@pytest.fixture(scope="module")
def edge_patch():
    """A 1.5 mm wall patch held on three sides; its free x1 edge is the wound edge."""
    mesh = box_mesh((0.012, 0.01, 0.0015), (12, 10, 3))
    fixed = np.concatenate([mesh.node_sets[k] for k in ("x0", "y0", "y1")])
    model = TissueModel(mesh, Material(20e3, 0.45), fixed)
    model.precompute(use_cache=False)
    return model


def stitch(model, parameters):
    needle = Needle.curved()
    suturing = SuturingPass(needle, [0.0105, 0.0051, 0.0015], [0, 0, 1], [1, 0, 0], parameters)
    device = ScriptedDevice(suturing.pose_and_grip)
    interaction = NeedleInteraction(model, needle, forces=PAPER)
    events, lateral = [], []
    for tick in range(int(suturing.duration * 1000) + 1):
        t = tick / 1000
        sample = device.read(t)
        events += interaction.hold(t, Pose(sample.position, sample.rotation), sample.pressed(0))
        if tick % 33 == 0:
            events += interaction.graphics_step(t)
        if tick % 2 == 0:
            step = interaction.fem_step(t)
            events += step.events
            if interaction.state in ("pierced", "exited"):
                lateral.append(np.linalg.norm(step.needle_force))
    return events, np.array(lateral), suturing


def test_scripted_suturing_pass_is_a_whole_stitch(edge_patch):
    events, _, suturing = stitch(edge_patch, SuturingPassParameters())
    assert [e.kind for e in events] == [
        "contact_start",
        "pierce",
        "exit",
        "release",
        "regrab",
        "pull_through",
    ]
    assert events[0].entry_angle_deg < 5.0
    release = events[3].time
    assert release == pytest.approx(suturing.phases["regrab"][0], abs=2e-3)


def test_levering_loads_the_wall_more_than_rotating(edge_patch):
    """Pushing the curved needle straight instead of turning the wrist drags the entry point."""
    _, rotating, _ = stitch(edge_patch, SuturingPassParameters(wrist_rotation=1.0))
    _, levering, _ = stitch(edge_patch, SuturingPassParameters(wrist_rotation=0.6))
    assert np.percentile(levering, 90) > 2 * np.percentile(rotating, 90)


def test_suturing_pass_parameters_shape_the_motion():
    needle = Needle.curved()
    base = SuturingPass(needle, [0, 0, 0], [0, 0, 1], [1, 0, 0])
    shaky = SuturingPass(
        needle, [0, 0, 0], [0, 0, 1], [1, 0, 0], SuturingPassParameters(tremor_amplitude=2e-4, seed=3)
    )
    again = SuturingPass(
        needle, [0, 0, 0], [0, 0, 1], [1, 0, 0], SuturingPassParameters(tremor_amplitude=2e-4, seed=3)
    )
    t = 1.234
    offset = shaky.pose_and_grip(t)[0].position - base.pose_and_grip(t)[0].position
    assert 0 < np.abs(offset).max() <= 2e-4
    np.testing.assert_array_equal(shaky.pose_and_grip(t)[0].position, again.pose_and_grip(t)[0].position)
    hesitant = SuturingPass(
        needle, [0, 0, 0], [0, 0, 1], [1, 0, 0], SuturingPassParameters(hesitations=2, hesitation_time=0.5)
    )
    assert hesitant.duration == pytest.approx(base.duration + 1.0)
    tilted = SuturingPass(needle, [0, 0, 0], [0, 0, 1], [1, 0, 0], SuturingPassParameters(entry_angle_deg=30))
    at_entry = tilted.pose_and_grip(tilted.phases["insertion"][0])[0]
    np.testing.assert_allclose(needle.world_vertices(at_entry)[0], [0, 0, 0], atol=1e-12)
    tangent = needle.tip_tangent(at_entry)
    assert math.degrees(math.acos(-tangent[2])) == pytest.approx(30.0, abs=1e-9)
    # restricted access: the hand descends along the approach, onto the same pose at entry
    side = SuturingPass(needle, [0, 0, 0], [0, 0, 1], [1, 0, 0], approach=[0, 1, 1])
    start, entry = (side.pose_and_grip(t)[0].position for t in (0.0, side.phases["insertion"][0]))
    np.testing.assert_allclose(entry, base.pose_and_grip(base.phases["insertion"][0])[0].position, atol=1e-15)
    np.testing.assert_allclose(start - entry, side.p.approach_distance * np.array([0, 1, 1]) / math.sqrt(2))
    with pytest.raises(DeviceError, match="approach from outside the wall"):
        SuturingPass(needle, [0, 0, 0], [0, 0, 1], [1, 0, 0], approach=[1, 0, -0.2])


@settings(max_examples=200, deadline=None)
@given(
    axis=st.tuples(*[st.floats(-1, 1)] * 3).filter(lambda v: sum(x * x for x in v) > 1e-4),
    centre=st.tuples(*[st.floats(-0.05, 0.05)] * 3),
    start=st.tuples(*[st.floats(-0.05, 0.05)] * 3),
    tilt=st.floats(-math.pi, math.pi),
    angle=st.floats(-4 * math.pi, 4 * math.pi),
)
def test_a_turn_about_a_fixed_axis_is_the_composed_rotation(axis, centre, start, tilt, angle):
    # Independent form: rotate the pose's offset from the centre and its frame by rotation_about.
    pose = Pose(np.array(start), rotation_about([0.3, -0.2, 1.0], tilt))
    turned = TurnAbout(axis, centre, pose).pose(angle)
    expected_rotation = rotation_about(axis, angle) @ pose.rotation
    expected_position = np.array(centre) + rotation_about(axis, angle) @ (pose.position - centre)
    np.testing.assert_allclose(turned.rotation, expected_rotation, atol=1e-14)
    np.testing.assert_allclose(turned.position, expected_position, atol=1e-15)
    Pose(turned.position, turned.rotation)  # still a proper rotation: the checked constructor accepts it


def test_a_turn_needs_an_axis():
    with pytest.raises(NeedleError, match="non-zero axis"):
        TurnAbout([0.0, 0.0, 0.0], [0.0, 0.0, 0.0], Pose.identity())


@settings(max_examples=100, deadline=None)
@given(
    axis=st.tuples(*[st.floats(-1, 1)] * 3).filter(lambda v: sum(x * x for x in v) > 1e-4),
    angle=st.floats(0.0, math.pi),
    shift=st.tuples(*[st.floats(-0.05, 0.05)] * 3),
    fraction=st.floats(0.0, 1.0),
)
def test_a_blended_pose_turns_about_one_axis_and_ends_where_it_should(axis, angle, shift, fraction):
    """sim.devices.scripted.blend_poses: the ends exactly, a proper rotation between, its angle from
    the start a share of the whole turn (half turns included)."""
    from sim.devices.scripted import blend_poses

    start = Pose.unchecked(np.zeros(3), rotation_about(np.array([0.0, 0.0, 1.0]), 0.3))
    turn = rotation_about(np.asarray(axis) / np.linalg.norm(axis), angle)
    stop = Pose.unchecked(np.asarray(shift), start.rotation @ turn)
    np.testing.assert_allclose(blend_poses(start, stop, 0.0).rotation, start.rotation, atol=1e-12)
    np.testing.assert_allclose(blend_poses(start, stop, 1.0).rotation, stop.rotation, atol=1e-9)
    np.testing.assert_allclose(blend_poses(start, stop, 1.0).position, stop.position, atol=1e-15)
    middle = blend_poses(start, stop, fraction).rotation
    np.testing.assert_allclose(middle.T @ middle, np.eye(3), atol=1e-12)
    turned = math.acos(min(max((np.trace(start.rotation.T @ middle) - 1) / 2, -1.0), 1.0))
    assert turned == pytest.approx((0.5 - 0.5 * math.cos(math.pi * fraction)) * angle, abs=1e-6)


def test_a_row_of_passes_never_jumps_between_stitches():
    """Between two bites the hand moves smoothly: no step in holder position over any 1 ms tick is
    larger than the passes themselves make (a jump was 3.2 m/s of recorded tip speed)."""
    needle = Needle.curved()
    passes = [SuturingPass(needle, [0.0105, y, 0.0015], [0, 0, 1], [1, 0, 0]) for y in (0.003, 0.005, 0.007)]
    trajectory, total = sequence_of_passes(passes)
    positions = np.array([trajectory(t)[0].position for t in np.arange(0.0, total, 0.001)])
    speeds = np.linalg.norm(np.diff(positions, axis=0), axis=1) / 0.001
    assert speeds.max() < 0.1, speeds.max()  # m/s: a hand's speed, not a teleport
