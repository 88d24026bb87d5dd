"""Insertion and force metrics of scripted passes run through the real simulator and recorder."""

import numpy as np
import pytest

from metrics import compute_session_metrics, from_recorded
from recorder import SessionWriter, open_session
from recorder.runtime import RuntimeRecorder
from sim.devices import ScriptedDevice, SuturingPass
from sim.devices.scripted import SuturingPassParameters
from sim.needle import Needle
from sim.needle.forces import NeedleForces
from sim.runtime import Simulation

PAPER = NeedleForces.paper()  # these tests drive the paper's soft tissue with its needle rule


def record_pass(directory, tissue, **parameters):
    needle = Needle.curved()
    suturing = SuturingPass(
        needle, [0.0105, 0.0051, 0.0015], [0, 0, 1], [1, 0, 0], SuturingPassParameters(**parameters)
    )
    writer = SessionWriter(directory, {"session_id": directory.name, "participant_id": "p1", "label": "x"})
    run = RuntimeRecorder(writer).attach(
        Simulation(tissue, needle, ScriptedDevice(suturing.pose_and_grip), forces=PAPER)
    )
    run.run_simulated(suturing.duration)
    writer.close()
    return open_session(directory), suturing


@pytest.fixture(scope="module")
def recorded(wall_patch_biphase, tmp_path_factory):
    root = tmp_path_factory.mktemp("sessions")
    return {
        (angle, speed): record_pass(root / f"a{angle}-v{speed}", wall_patch_biphase, entry_angle_deg=angle,
                                    insertion_speed=speed)
        for angle, speed in ((20.0, 0.004), (5.0, 0.008))
    }  # fmt: skip


@pytest.mark.parametrize("angle, speed", [(20.0, 0.004), (5.0, 0.008)])
def test_insertion_metrics_recover_the_scripted_angle_and_speed(recorded, angle, speed):
    session, suturing = recorded[(angle, speed)]
    row = compute_session_metrics([session]).iloc[0]
    assert row["session_id"] == f"a{angle}-v{speed}" and row["participant_id"] == "p1"
    assert row["entry_angle_error_deg"] == pytest.approx(angle, abs=3.0)
    assert row["tip_speed_after_pierce"] == pytest.approx(speed, rel=0.05)
    assert row["attempts"] == 0 and row["regrabs"] == 1
    pierce = session.events.to_pandas().query("kind == 'pierce'")["time"].iloc[0]
    contact = session.events.to_pandas().query("kind == 'contact_start'")["time"].iloc[0]
    assert row["contact_to_pierce_time"] == pytest.approx(pierce - contact)
    assert row["task_time"] == pytest.approx(suturing.duration, abs=2e-3)


def test_force_metrics_match_the_recorded_stream(recorded):
    session, _ = recorded[(20.0, 0.004)]
    row = compute_session_metrics([session]).iloc[0]
    samples = session.samples.to_pandas()
    # the tissue's reaction on the needle (schema 2), not the force the device was sent after its delay
    magnitude = np.linalg.norm(samples[["reaction_x", "reaction_y", "reaction_z"]].to_numpy(), axis=1)
    touching = samples["pierced"].to_numpy() > 0
    assert row["peak_force"] == pytest.approx(magnitude.max())
    assert row["mean_force"] == pytest.approx(magnitude[touching].mean())
    assert row["rms_force"] == pytest.approx(np.sqrt(np.mean(magnitude[touching] ** 2)))
    pierce = session.events.to_pandas().query("kind == 'pierce'")["time"].iloc[0]
    assert row["force_at_insertion"] == pytest.approx(np.interp(pierce, samples["time"], magnitude))
    assert row["peak_force"] > 0


def test_slower_more_perpendicular_pass_is_not_scored_worse_on_angle(recorded):
    table = compute_session_metrics([from_recorded(s) for s, _ in recorded.values()])
    by_angle = table.set_index("session_id")["entry_angle_error_deg"]
    assert by_angle["a5.0-v0.008"] < by_angle["a20.0-v0.004"]
