"""The needle's load, puncture and passage forces: mesh-converged stiffness, credible magnitudes."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import quad
from scipy.special import jv

from sessions.tasks import task_preset, task_spec, tissue_for
from sim.devices import ScriptedDevice, SuturingPass
from sim.devices.scripted import SuturingPassParameters
from sim.fem import Material, TissueModel
from sim.fem.kernel import (
    KernelContact,
    biweight_halfspace_factor,
    flat_punch_stiffness,
    kernel_at,
    normal_near_field,
)
from sim.mesh import box_mesh, grid_box_mesh, refined_coordinates
from sim.needle import Needle
from sim.needle.forces import NeedleForces, NeedleForcesError
from sim.runtime import Simulation

WIRE_RADIUS = 1.25e-4
SOFT = Material(20e3, 0.45)
KERNEL_BOX = TissueModel(box_mesh(0.01, 12), SOFT, box_mesh(0.01, 12).node_sets["z0"])


def normal_stiffness(tissue, point, normal=(0.0, 0.0, 1.0), radius=1e-3, near_field=True):
    kernel = kernel_at(tissue, point, normal, radius)
    field = normal_near_field(kernel, WIRE_RADIUS) if near_field else np.zeros((3, 3))
    contact = KernelContact(tissue, [kernel], [field])
    n = np.asarray(normal, dtype=float)
    return float(n @ contact.stiffness @ n)


def graded_cube(fine):
    xs = refined_coordinates(0.01, 1e-3, fine, 0.0035, 0.0065)
    mesh = grid_box_mesh(xs, xs, refined_coordinates(0.01, 1e-3, fine, 0.007, 0.01))
    return TissueModel(mesh, SOFT, mesh.node_sets["z0"])


def graded_patch(fine):
    """The wall-stitch patch (12 x 10 x 1.5 mm, held on three sides) refined around the stitch."""
    mesh = grid_box_mesh(
        refined_coordinates(0.012, 1e-3, fine, 0.0085, 0.012),
        refined_coordinates(0.01, 1e-3, fine, 0.0031, 0.0071),
        refined_coordinates(0.0015, 1e-3, fine, 0.0, 0.0015),
    )
    fixed = np.concatenate([mesh.node_sets[k] for k in ("x0", "y0", "y1")])
    return TissueModel(mesh, SOFT, fixed)


@settings(max_examples=30, deadline=None)
@given(
    forces=st.lists(st.floats(-2.0, 2.0), min_size=6, max_size=6),
    x=st.floats(0.003, 0.0045),  # the two kernels apart (at x = 5 mm they coincide: no compliance inverse)
)
def test_the_drive_of_kernel_forces_is_that_of_their_nodal_forces(forces, x):
    """Each FEM step's penalty drive (what the display, the scene log and the replay drive) is formed
    through G_JJ M for the kernel set (a (3k x 3m) product) rather than G_JJ times the nodal forces
    (3k x 3k): the same drive for two kernels' forces, to rounding."""
    kernels = [
        kernel_at(KERNEL_BOX, (x, 0.005, 0.01), (0, 0, 1), 1e-3),
        kernel_at(KERNEL_BOX, (0.005, x, 0.01), (0, 0, 1), 1e-3),
    ]
    contact = KernelContact(KERNEL_BOX, kernels, [np.zeros((3, 3))] * 2)
    f = np.asarray(forces)
    r = contact.nodal_forces(f).reshape(-1)  # a = G_JJ R + R / C, with the nodal forces formed first
    expected = (KERNEL_BOX.compliance_block(contact.nodes) @ r + r / contact.penalty).reshape(-1, 3)
    np.testing.assert_allclose(
        contact.kernel_drive(f), expected, rtol=0, atol=1e-12 * max(abs(expected).max(), 1e-30)
    )


def test_halfspace_factor_is_the_hankel_integral():
    """beta from the closed form equals (2304 / pi) x the J3^2 / t^6 integral done by quadrature."""
    integral = quad(lambda t: jv(3, t) ** 2 / t**6, 0, 400, limit=4000)[0]
    assert biweight_halfspace_factor() == pytest.approx(2304 / math.pi * integral, rel=1e-6)
    # and the same transform gives the textbook uniform-pressure value 16 / (3 pi^2) for a disc
    uniform = 4 / math.pi * quad(lambda t: jv(1, t) ** 2 / t**2, 0, 2000, limit=20000)[0]
    assert uniform == pytest.approx(16 / (3 * math.pi**2), rel=1e-3)


def test_needle_stiffness_converges_on_the_cube_to_the_flat_punch():
    """Kernel + near field: < 3 % change between the two finest refinements, within 5 % of 2 a E*."""
    coarse, fine = (normal_stiffness(graded_cube(h), [0.005, 0.005, 0.01]) for h in (0.33e-3, 0.25e-3))
    punch = flat_punch_stiffness(WIRE_RADIUS, SOFT.youngs_modulus / (1 - SOFT.poisson_ratio**2))
    assert abs(fine - coarse) / fine < 0.03
    assert fine == pytest.approx(punch, rel=0.05)


def test_needle_stiffness_converges_on_a_vessel_wall_patch():
    points = [0.0105, 0.0051, 0.0015]
    coarse, fine = (normal_stiffness(graded_patch(h), points) for h in (0.33e-3, 0.25e-3))
    assert abs(fine - coarse) / fine < 0.03


def test_barycentric_rule_has_no_converged_stiffness_and_the_kernel_does():
    """What was seen: the three-node rule's stiffness is proportional to the element size; the
    kernel's barely moves, and does not depend on where in a triangle the tip lands."""

    def three_node(divisions):
        mesh = box_mesh(0.01, divisions)
        tissue = TissueModel(mesh, SOFT, mesh.node_sets["z0"])
        top = np.flatnonzero(np.isclose(mesh.points[:, 2], 0.01))
        nearest = top[np.argmin(np.linalg.norm(mesh.points[top] - [0.005, 0.005, 0.01], axis=1))]
        return float(tissue.contact([nearest]).stiffness[2, 2])

    assert three_node(10) / three_node(20) > 1.8  # halving h halves the rule's stiffness (ratio 2)
    tissue = graded_cube(0.33e-3)
    vertex = normal_stiffness(tissue, [0.005, 0.005, 0.01])
    h = 0.33e-3 * 3 / math.ceil(3 / 0.33 - 1e-9)  # the fine cell there
    centroid = normal_stiffness(tissue, [0.005 + h / 3, 0.005 + 2 * h / 3, 0.01])
    assert abs(vertex - centroid) / vertex < 0.03


def test_kernel_falls_back_to_the_triangle_when_the_mesh_is_coarser_than_it():
    mesh = box_mesh(0.01, 4)
    tissue = TissueModel(mesh, SOFT, mesh.node_sets["z0"])
    kernel = kernel_at(
        tissue, [0.004, 0.0041, 0.01], [0, 0, 1], 1e-3, fallback=(np.array([1, 2]), [0.3, 0.7])
    )
    assert kernel.nodes.tolist() == [1, 2] and kernel.weights.sum() == pytest.approx(1.0)


@settings(max_examples=40, deadline=None)
@given(
    x=st.floats(0.0, 0.01),
    y=st.floats(0.0, 0.01),
    radius=st.floats(2e-4, 3e-3),
    tilt=st.floats(-0.9, 0.9),
)
def test_kernel_nodes_and_weights_are_those_of_a_scan_of_every_surface_node(x, y, radius, tilt):
    """The kernel finds its nodes through a tree; a scan of every free surface node (the rule as
    written: within the radius, vertex normal within 60 degrees) gives the same nodes and weights."""
    tissue = KERNEL_BOX
    normal = np.array([tilt, 0.0, 1.0]) / np.hypot(tilt, 1.0)
    centre = np.array([x, y, 0.01])
    mesh = tissue.mesh
    free = np.setdiff1d(mesh.surface_nodes, tissue.clamped_nodes)
    distance = np.linalg.norm(mesh.points[free] - centre, axis=1)
    normals = tissue.vertex_normals[free] / np.linalg.norm(tissue.vertex_normals[free], axis=1, keepdims=True)
    inside = (distance < radius) & (normals @ normal >= 0.5)
    weights = (1 - (distance[inside] / radius) ** 2) ** 2
    corners = mesh.points[mesh.surface_triangles]
    areas = 0.5 * np.linalg.norm(
        np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1
    )
    nodal = np.zeros(mesh.n_nodes)
    np.add.at(nodal, mesh.surface_triangles.ravel(), np.repeat(areas / 3, 3))
    weights = weights * nodal[free[inside]]
    fallback = (np.array([0]), np.array([1.0]))
    kernel = kernel_at(tissue, centre, normal, radius, fallback=fallback)
    if not inside.any() or not (weights > 0).any():
        assert kernel.nodes.tolist() == [0]
        return
    keep = weights > 0
    np.testing.assert_array_equal(kernel.nodes, free[inside][keep])
    np.testing.assert_allclose(kernel.weights, weights[keep] / weights[keep].sum(), rtol=1e-12)


def test_passage_resistance_has_a_stick_band_cutting_only_forward_and_an_emergence_ramp():
    forces = NeedleForces()
    half = forces.stick_speed / 2
    inside = 1e-3
    assert forces.axial_resistance(0.0, inside, True, 0.0) == 0.0
    slow = forces.axial_resistance(half, inside, False, 0.0)
    assert slow == pytest.approx(
        0.5 * forces.friction_per_length * inside + forces.viscous_coefficient * half
    )
    fast = forces.axial_resistance(0.005, inside, True, 0.0)
    assert fast == pytest.approx(forces.friction_per_length * inside + forces.cutting_force + 0.005 * 0.5)
    back = forces.axial_resistance(-0.005, inside, True, 0.0)
    assert back == pytest.approx(-forces.friction_per_length * inside - 0.005 * 0.5)  # no cutting backwards
    ramp = forces.axial_resistance(0.0, 0.0, False, forces.emergence_ramp / 2)
    assert ramp == pytest.approx(forces.emergence_force / 2)


@pytest.mark.parametrize(
    "changes",
    [{"load": "springs"}, {"kernel_radius": 0.0}, {"puncture_force": -1.0}, {"cutting_force": math.nan}],
)
def test_needle_force_parameters_are_checked(changes):
    with pytest.raises(NeedleForcesError):
        NeedleForces(**changes)


@pytest.fixture(scope="module")
def wall_stitch():
    return tissue_for(task_spec("wall-stitch"), None)


def stitch_forces(tissue, parameters):
    """(tip depth below the entry plane (m), needle force (N), state) per haptic tick, and the events."""
    spec = task_spec("wall-stitch")
    suturing = SuturingPass(Needle.curved(), spec.entry, spec.normal, spec.bite_direction, parameters)
    simulation = Simulation(
        tissue,
        Needle.curved(),
        ScriptedDevice(suturing.pose_and_grip),
        forces=task_preset(task_spec("wall-stitch")).forces,
    )
    rows = []

    def record(now, sample, force, fem):
        if fem is not None:
            rows.append(
                (
                    spec.entry[2] - fem.needle_vertices[0][2],
                    float(np.linalg.norm(fem.needle_force)),
                    fem.state,
                )
            )

    simulation.on_sample = record
    result = simulation.run_simulated(suturing.duration)
    depth, force, state = (np.array(column) for column in zip(*rows, strict=True))
    return depth, force, state, [e.kind for e in result.events]


def test_expert_pass_has_credible_puncture_and_pull_through_forces(wall_stitch):
    depth, force, state, events = stitch_forces(wall_stitch, SuturingPassParameters())
    assert ["contact_start", "pierce", "exit", "release", "regrab", "pull_through"] == [
        k for k in events if k not in ("stopped",)
    ]
    puncture = force[state == "contact"].max()
    assert 0.5 <= puncture <= 1.0
    pulling = force[(state == "exited") & (force > 0.01)]
    assert 0.1 <= np.median(pulling) <= 0.3
    assert force.max() <= 1.0  # nothing jumps when the needle is pulled clear
    pierced_at = np.flatnonzero(state == "pierced")[0]
    assert 0.7e-3 <= depth[pierced_at] <= 1.1e-3  # the wall is indented 0.7-1.1 mm before it gives


def test_perpendicular_pass_shows_two_peaks_entry_and_emergence(wall_stitch):
    """Frick et al. 2001's shape: a peak at puncture, a drop, a second (lower) peak as the tip comes
    out through the far surface, then the lower pull-through plateau."""
    _, force, state, _ = stitch_forces(wall_stitch, SuturingPassParameters())
    first = force[state == "contact"].max()
    in_wall = force[state == "pierced"][5:]  # the first FEM steps after the pierce still carry its force
    trough = in_wall[: len(in_wall) // 4].min()
    second = in_wall.max()
    after = np.median(force[(state == "exited") & (force > 0.01)])
    assert trough < 0.6 * first
    assert trough < 0.8 * second < second < first
    assert after < 0.5 * second


@pytest.mark.parametrize(
    "trainee",
    [
        SuturingPassParameters(wrist_rotation=0.5),
        SuturingPassParameters(hesitations=2, entry_angle_deg=15.0, wrist_rotation=0.7),
    ],
)
def test_levering_trainees_load_the_wall_more_than_the_expert(wall_stitch, trainee):
    """A needle levered instead of turned along its curve loads the wall sideways once it is through:
    the force while it crosses both walls is at least twice the expert's, the local stress passes the
    damage threshold and the wall gives way (a tear), at the bounded force, never beyond it."""
    _, expert, expert_state, expert_events = stitch_forces(wall_stitch, SuturingPassParameters())
    _, force, state, events = stitch_forces(wall_stitch, trainee)
    assert force[state == "exited"].max() > 2.0 * expert[expert_state == "exited"].max()
    assert "overstress" in events and "tear" in events
    assert "overstress" not in expert_events and "tear" not in expert_events
    assert force.max() <= task_preset(task_spec("wall-stitch")).forces.tear_force * 1.001


def test_a_steep_entry_skids_before_it_pierces(wall_stitch):
    """At 25 deg the tip's sideways push exceeds what friction holds (tan 25 deg = 0.47 > mu = 0.3):
    the tip slides on the surface, and it pierces on its normal force with the total force within the
    friction cone (before, the tip was glued sideways and the total overshot: 3.77 N at 0.84 N normal)."""
    _, force, state, events = stitch_forces(wall_stitch, SuturingPassParameters(entry_angle_deg=25.0))
    assert "pierce" in events
    forces = task_preset(task_spec("wall-stitch")).forces
    cone = math.sqrt(1.0 + forces.friction_coefficient**2) * forces.puncture_force
    assert force[state == "contact"].max() <= cone * 1.01
