"""The runtime streams local stress and stretch live; the post-hoc derivation is its oracle."""

import dataclasses

import numpy as np
import pytest

from metrics.signals.tissue import session_forces, with_tissue_fields
from metrics.streams import from_recorded
from recorder import SessionWriter, open_session
from recorder.runtime import RuntimeRecorder
from sessions.tasks import task_preset, task_spec, tissue_for
from sim.devices import ScriptedDevice, SuturingPass
from sim.devices.scripted import SuturingPassParameters
from sim.needle import Needle
from sim.needle.forces import NeedleForces
from sim.runtime import Simulation

FORCES = task_preset(task_spec("wall-stitch")).forces


def record(folder, tissue, parameters, forces=FORCES):
    spec = task_spec("wall-stitch")
    suturing = SuturingPass(Needle.curved(), spec.entry, spec.normal, spec.bite_direction, parameters)
    header = {
        "session_id": folder.name,
        "participant_id": "p",
        "label": "x",
        "task": "wall-stitch",
        "needle_forces": forces.as_dict(),
        "placement": spec.placement,  # as sessions.running.runner records it
    }
    writer = SessionWriter(folder, header, flush_interval=0.1)
    simulation = Simulation(tissue, Needle.curved(), ScriptedDevice(suturing.pose_and_grip), forces=forces)
    RuntimeRecorder(writer).attach(simulation).run_simulated(suturing.duration)
    writer.close()
    return from_recorded(open_session(folder))


@pytest.fixture(scope="module")
def wall():
    return tissue_for(task_spec("wall-stitch"), None)


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
    # the contact point rebuilt from the recorded weights differs from the runtime's by rounding (1e-19 m),
    # which at the first touch is 1e-11 Pa on a zero stress: hence the absolute tolerance
    np.testing.assert_allclose(
        derived.local_stress[indenting], streams.local_stress[indenting], rtol=1e-9, atol=1e-6
    )
    np.testing.assert_allclose(derived.stretch[indenting], streams.stretch[indenting], rtol=1e-9, atol=1e-12)
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


def _bite(task: str, parameters: SuturingPassParameters, nearer_edge: float = 0.0):
    """A scripted bite on ``task``'s vessel, ``nearer_edge`` (m) closer to the wound than its mark."""
    spec = task_spec(task)
    entry = np.asarray(spec.entry) + nearer_edge * np.asarray(spec.bite_direction)
    radius = float(np.linalg.norm(spec.entry[:2]))
    entry[:2] *= radius / np.linalg.norm(entry[:2])  # back onto the adventitia
    normal = np.array([entry[0], entry[1], 0.0]) / radius
    towards_wound = np.array([normal[1], -normal[0], 0.0])
    return SuturingPass(Needle.curved(), entry, normal, towards_wound, parameters)


def test_the_wound_edge_stress_is_live_and_a_levered_bite_near_the_edge_raises_edge_overstress():
    """The interrupted stitch watches the wound's cut faces within 3 mm of the needle each FEM step:
    the live value equals the edge-only replay of the step's drive (the metric's path) on the same
    elements; an expert bite 1.5 mm from the edge stays under the preset's threshold, a levered bite
    0.6 mm from it crosses it once (an ``edge_overstress`` event)."""
    from metrics.signals.passage import WoundEdgeStress
    from sessions.tasks import task_simulation

    replay = WoundEdgeStress(tissue_for(task_spec("interrupted-stitch"), None))
    results = {}
    for name, parameters, nearer in (
        ("expert", SuturingPassParameters(), 0.0),
        ("levered near the edge", SuturingPassParameters(wrist_rotation=0.4), 0.9e-3),
    ):
        suturing = _bite("interrupted-stitch", parameters, nearer)
        simulation = task_simulation(task_spec("interrupted-stitch"), ScriptedDevice(suturing.pose_and_grip))
        interaction = simulation.interaction
        checked, peaks = [], []
        fem_step = interaction.fem_step

        def watched_step(time, fem_step=fem_step, interaction=interaction, checked=checked, peaks=peaks):
            step = fem_step(time)
            peaks.append(interaction.wound_edge_stress)
            if interaction.last_contact is not None and len(checked) < 5 and time > 1.2:
                nodes, drive = interaction.last_contact
                stress = replay.stress(nodes, drive, interaction.tip_speed, interaction.soft_share)
                watched = np.isin(replay.elements, interaction.watched_edge_elements)
                checked.append((interaction.wound_edge_stress, float(stress[watched].max())))
            return step

        interaction.fem_step = watched_step
        events = [e.kind for e in simulation.run_simulated(suturing.duration).events]
        results[name] = (events, np.nanmax(peaks), checked)
    expert, levered = results["expert"], results["levered near the edge"]
    assert expert[2] and levered[2]
    for live, replayed in expert[2] + levered[2]:
        assert live == pytest.approx(replayed, rel=1e-9)
    assert "edge_overstress" not in expert[0] and expert[1] < 0.6e6
    assert levered[0].count("edge_overstress") >= 1 and levered[1] > 0.6e6
