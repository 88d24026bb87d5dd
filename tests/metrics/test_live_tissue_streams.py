"""The runtime streams local stress and stretch live; the post-hoc derivation is its oracle."""

import dataclasses

import numpy as np
import pytest

from metrics.streams import from_recorded
from metrics.tissue import session_forces, with_tissue_fields
from recorder import SessionWriter, open_session
from recorder.runtime import RuntimeRecorder
from sessions.tasks import task_preset, task_spec, tissue_for
from sim.devices import ScriptedDevice, SuturingPass
from sim.devices.scripted import SuturingPassParameters
from sim.needle import Needle
from sim.needle_forces import NeedleForces
from sim.runtime import Simulation

FORCES = task_preset("wall-stitch").forces


def record(folder, tissue, parameters, forces=FORCES):
    spec = task_spec("wall-stitch")
    suturing = SuturingPass(Needle.curved(), spec.entry, spec.normal, spec.bite_direction, parameters)
    header = {
        "session_id": folder.name,
        "participant_id": "p",
        "label": "x",
        "task": "wall-stitch",
        "needle_forces": forces.as_dict(),
        "placement": spec.placement,  # as sessions.runner records it
    }
    writer = SessionWriter(folder, header, flush_interval=0.1)
    simulation = Simulation(tissue, Needle.curved(), ScriptedDevice(suturing.pose_and_grip), forces=forces)
    RuntimeRecorder(writer).attach(simulation).run_simulated(suturing.duration)
    writer.close()
    return from_recorded(open_session(folder))


@pytest.fixture(scope="module")
def wall():
    return tissue_for("wall-stitch", None)


@pytest.mark.parametrize(
    "parameters",
    [SuturingPassParameters(), SuturingPassParameters(entry_angle_deg=20.0, tremor_amplitude=2e-4)],
)
def test_recorded_stress_and_stretch_are_never_nan_in_tissue_and_equal_the_derivation(
    wall, tmp_path, parameters
):
    streams = record(tmp_path / "s", wall, parameters)
    touching = streams.needle_state > 0
    assert touching.sum() > 100
    assert np.all(np.isfinite(streams.local_stress[touching])) and np.all(
        np.isfinite(streams.stretch[touching])
    )
    assert np.all(np.isnan(streams.local_stress[~touching]))
    assert session_forces(streams) == FORCES
    derived = with_tissue_fields(dataclasses.replace(streams, local_stress=None, stretch=None), wall)
    indenting = streams.needle_state == 1
    np.testing.assert_allclose(derived.local_stress[indenting], streams.local_stress[indenting], rtol=1e-9)
    np.testing.assert_allclose(derived.stretch[indenting], streams.stretch[indenting], rtol=1e-9)
    # the insertion stress field is derived for sessions that streamed the per-tick values too
    assert with_tissue_fields(streams, wall).stress_field is not None


def test_a_paper_rule_session_derives_its_fields_with_the_paper_rule(wall, tmp_path):
    paper = NeedleForces.paper().with_(puncture_force=0.8)  # barycentric load, the kernel's threshold
    streams = record(tmp_path / "p", wall, SuturingPassParameters(), paper)
    indenting = streams.needle_state == 1
    derived = with_tissue_fields(dataclasses.replace(streams, local_stress=None, stretch=None), wall)
    np.testing.assert_allclose(derived.stretch[indenting], streams.stretch[indenting], rtol=1e-9)
    # the paper's reconstruction reports the elements within 2 mm, the live stream those within 1 mm
    assert np.all(derived.local_stress[indenting] >= streams.local_stress[indenting] * (1 - 1e-9))


def test_levering_raises_an_overstress_event(wall, tmp_path):
    forces = FORCES.with_(damage_stress=1.0e6)
    spec = task_spec("wall-stitch")
    events = {}
    for name, parameters in (
        ("expert", SuturingPassParameters()),
        ("lever", SuturingPassParameters(wrist_rotation=0.4)),
    ):
        suturing = SuturingPass(Needle.curved(), spec.entry, spec.normal, spec.bite_direction, parameters)
        simulation = Simulation(wall, Needle.curved(), ScriptedDevice(suturing.pose_and_grip), forces=forces)
        events[name] = [e.kind for e in simulation.run_simulated(suturing.duration).events]
    assert "overstress" not in events["expert"]
    assert "overstress" in events["lever"]
