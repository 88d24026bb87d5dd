"""The recorded stretch is the stretch of the wall the display draws (issue 43, item 4).

Before, ``stretch`` put the passage forces through the soft phase's compliance whatever the phase split
and divided by the wall's depth: 2.9-5.5 after piercing while the shown displacement was ~0.2 mm.
Now it is the largest deformed-over-rest length of the edges of the elements around the contact, in
the field the display solves for the same loads.
"""

from types import SimpleNamespace

import numpy as np
import pytest

from sessions.tasks import task_preset, task_spec, tissue_for
from sim.devices import ScriptedDevice, SuturingPass
from sim.devices.scripted import SuturingPassParameters
from sim.needle import Needle
from sim.runtime import Simulation
from sim.runtime.display import DisplayScene

EDGES = np.array([[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]])


@pytest.fixture(scope="module")
def wall():
    return tissue_for(task_spec("wall-stitch"), None)


def edge_stretch(mesh, elements, points):
    pairs = mesh.tets[elements][:, EDGES].reshape(-1, 2)
    rest = np.linalg.norm(mesh.points[pairs[:, 1]] - mesh.points[pairs[:, 0]], axis=1)
    now = np.linalg.norm(points[pairs[:, 1]] - points[pairs[:, 0]], axis=1)
    return float((now / rest).max())


@pytest.mark.parametrize(
    "parameters",
    [SuturingPassParameters(), SuturingPassParameters(wrist_rotation=0.5)],
    ids=["expert", "levering"],
)
def test_stretch_equals_the_shown_walls_edge_stretch_around_the_contact(wall, parameters):
    spec = task_spec("wall-stitch")
    suturing = SuturingPass(Needle.curved(), spec.entry, spec.normal, spec.bite_direction, parameters)
    simulation = Simulation(
        wall,
        Needle.curved(),
        ScriptedDevice(suturing.pose_and_grip),
        forces=task_preset(task_spec("wall-stitch")).forces,
    )
    seen = {"contact": [], "pierced": [], "exited": []}

    def compare(now, fem):
        stress = simulation.interaction._stress
        if fem.state not in seen or not len(fem.contact_nodes) or stress is None:
            return
        scene = DisplayScene(wall, None)  # a fresh one: a full solve for these loads
        snapshot = SimpleNamespace(
            loads=(fem.contact_nodes, fem.reaction_forces, fem.soft_share),
            needle_vertices=fem.needle_vertices,
        )
        shown = scene.frame_of(snapshot).points
        seen[fem.state].append((fem.stretch, edge_stretch(wall.mesh, stress.elements, shown)))

    simulation.on_graphics = compare
    simulation.run_simulated(suturing.duration)
    for state, pairs in seen.items():
        assert len(pairs) >= 2, state
        recorded, drawn = np.array(pairs).T
        np.testing.assert_allclose(recorded, drawn, rtol=1e-9)
        assert recorded.max() <= 1.6  # a real stretch (the expert bound), not 2.9-5.5
