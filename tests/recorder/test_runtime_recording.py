"""A running simulation recorded through the real writer, in simulated and in real time."""

import numpy as np
import pytest

from recorder import SessionWriter, open_session
from recorder.runtime import RuntimeRecorder, quaternion_of
from sim.devices import ScriptedDevice, SuturingPass
from sim.devices.scripted import quaternion_matrix
from sim.needle import Needle, rotation_about
from sim.needle.forces import NeedleForces
from sim.runtime import Simulation

# the real-time clock needs the machine to itself (scripts/test runs these after the rest)
pytestmark = pytest.mark.exclusive

PAPER = NeedleForces.paper()  # these tests drive the paper's soft tissue with its needle rule


@pytest.fixture(scope="module")
def setup(wall_patch_biphase):
    needle = Needle.curved()
    suturing = SuturingPass(needle, [0.0105, 0.0051, 0.0015], [0, 0, 1], [1, 0, 0])
    return wall_patch_biphase, needle, suturing


@pytest.mark.parametrize("clock", ["simulated", "realtime"])
def test_every_tick_and_event_is_recorded(tmp_path, setup, clock):
    tissue, needle, suturing = setup
    writer = SessionWriter(
        tmp_path / "s", {"participant": "synthetic-01", "clock": clock}, flush_interval=0.05
    )
    simulation = RuntimeRecorder(writer).attach(
        Simulation(tissue, needle, ScriptedDevice(suturing.pose_and_grip), forces=PAPER)
    )
    duration = 2.5
    result = simulation.run_simulated(duration) if clock == "simulated" else simulation.run_realtime(duration)
    writer.close()
    session = open_session(tmp_path / "s")
    samples = session.samples
    ticks = sum(1 for t in result.haptic.time if t <= duration + 1e-9)
    assert samples.num_rows == ticks
    np.testing.assert_allclose(samples.column("force_z").to_numpy(), result.haptic.force[:ticks, 2])
    states = samples.column("pierced").to_numpy()
    assert {0, 1, 2} <= set(states.tolist())
    kinds = session.events.column("kind").to_pylist()
    assert "contact_start" in kinds and "pierce" in kinds
    contact_rows = samples.filter(samples.column("contact_triangle").to_numpy() >= 0)
    assert contact_rows.num_rows > 0
    # issue 21 (6): local stress and stretch streamed in real time too, never NaN in the tissue
    touching = states > 0
    for column in ("local_stress", "stretch"):
        assert np.all(np.isfinite(samples.column(column).to_numpy()[touching])), column


def test_quaternion_of_round_trips():
    for axis, angle in (([0, 0, 1], 0.3), ([1, -1, 0.5], 2.5), ([0, 1, 0], 3.1)):
        rotation = rotation_about(axis, angle)
        np.testing.assert_allclose(quaternion_matrix(np.array(quaternion_of(rotation))), rotation, atol=1e-12)
