"""The subordinate hand's grasp: known answers from sparse FEM solves with the grasped dofs prescribed."""

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from hypothesis import given, settings
from hypothesis import strategies as st

from sim.collision.mesh import CollisionMesh
from sim.fem import Material, TissueModel
from sim.fem.inverse.condensation import node_dofs
from sim.forceps import Forceps, ForcepsError, ForcepsInteraction, closest_surface_point, jaw_nodes
from sim.forceps.jaws import _closest_on_triangles
from sim.mesh import box_mesh


@pytest.fixture(scope="module")
def patch():
    """A 12 x 10 x 1.5 mm wall patch held on three sides; its free x1 side is the wound edge."""
    mesh = box_mesh((0.012, 0.01, 0.0015), (12, 10, 3))
    fixed = np.concatenate([mesh.node_sets[k] for k in ("x0", "y0", "y1")])
    return TissueModel(mesh, Material(20e3, 0.45), fixed)


def _dirichlet(model, loads, held, held_at, springs=()):
    """The sparse FEM answer: K0 (+ penalty springs C on ``springs``' dofs) u = f, with the dofs of
    ``held`` prescribed at ``held_at`` (eliminated), ``loads`` a full force vector. Returns (u, the
    reaction forces at the held dofs)."""
    stiffness = model.penalised_stiffness().tocsr()
    if len(springs):
        extra = np.zeros(stiffness.shape[0])
        extra[node_dofs(np.asarray(springs))] = model.penalty
        stiffness = (stiffness + sp.diags(extra)).tocsr()
    fixed = node_dofs(np.asarray(held))
    free = np.setdiff1d(np.arange(stiffness.shape[0]), fixed)
    u = np.zeros(stiffness.shape[0])
    u[fixed] = np.reshape(held_at, -1)
    rhs = loads[free] - stiffness[free][:, fixed] @ u[fixed]
    u[free] = spla.spsolve(stiffness[free][:, free].tocsc(), rhs)
    reactions = stiffness[fixed] @ u - loads[fixed]
    return u.reshape(-1, 3), reactions.reshape(-1, 3)


def _edge_nodes(model, count=4):
    """Free nodes on the wound edge's top corner line, the middle ones."""
    mesh = model.mesh
    edge = mesh.node_sets["x1"]
    top = edge[np.isclose(mesh.points[edge, 2], 0.0015)]
    top = top[np.argsort(mesh.points[top, 1])]
    middle = len(top) // 2
    return top[middle - count // 2 : middle + count - count // 2]


def _relative(a, b):
    return float(np.abs(a - b).max() / np.abs(b).max())


def test_a_grasped_patch_moved_by_d_gives_the_fem_solve_with_those_nodes_prescribed(patch):
    held = _edge_nodes(patch)
    d = np.array([0.4e-3, 0.1e-3, 0.8e-3])  # everting: up and out of the wound
    solution = patch.solve({}, prescribed={int(n): d for n in held}, full_field=True)
    no_loads = np.zeros(3 * patch.mesh.n_nodes)
    expected_u, expected_forces = _dirichlet(patch, no_loads, held, np.tile(d, (4, 1)))
    assert _relative(solution.displacement, expected_u) < 1e-9
    assert _relative(solution.reaction_forces, expected_forces) < 1e-9
    assert np.allclose(solution.displacement[held], d, rtol=0, atol=1e-15)  # held exactly, not by a penalty


def test_the_grasp_superposed_with_a_needle_contact_equals_the_joint_solve(patch):
    held = _edge_nodes(patch)
    mesh = patch.mesh
    top = mesh.node_sets["z1"]
    pressed = top[np.argsort(np.linalg.norm(mesh.points[top] - [0.0095, 0.005, 0.0015], axis=1))[:3]]
    pressed = np.setdiff1d(pressed, held)
    push = np.array([0.0, 0.0, -0.5e-3])
    d = np.array([0.3e-3, 0.0, 0.6e-3])
    solution = patch.solve(
        {int(n): push for n in pressed}, prescribed={int(n): d for n in held}, full_field=True
    )
    loads = np.zeros(3 * mesh.n_nodes)
    loads[node_dofs(pressed)] = patch.penalty * np.tile(push, len(pressed))
    expected_u, _ = _dirichlet(patch, loads, held, np.tile(d, (len(held), 1)), springs=pressed)
    assert _relative(solution.displacement, expected_u) < 1e-9
    # the penalty contacts' reactions: C (a - u) at their nodes
    expected_pressed = patch.penalty * (push - expected_u[pressed])
    assert _relative(solution.reaction_forces[: len(pressed)], expected_pressed) < 1e-9


def test_forceps_hold_their_nodes_where_the_hand_puts_them_under_the_needles_load_too(patch):
    collision = CollisionMesh(patch.mesh)
    forceps = ForcepsInteraction(patch, collision)
    mesh = patch.mesh
    jaw = np.array([0.012, 0.005, 0.00075])  # on the cut face of the wound edge, mid-wall
    forceps.hold(0.0, jaw, True)
    d = np.array([0.2e-3, 0.0, 0.7e-3])
    forceps.hold(0.01, jaw + d, True)
    top = mesh.node_sets["z1"]
    needle_nodes = top[np.argsort(np.linalg.norm(mesh.points[top] - [0.009, 0.005, 0.0015], axis=1))[:3]]
    needle_forces = np.array([[0.0, 0.0, -0.05], [0.0, 0.01, -0.05], [0.0, 0.0, -0.04]])
    step = forceps.fem_step(0.01, needle_nodes, needle_forces)
    assert [event.kind for event in step.events] == ["grasp"]
    loads = np.zeros(3 * mesh.n_nodes)
    loads[node_dofs(needle_nodes)] = needle_forces.reshape(-1)
    expected_u, expected_grasp = _dirichlet(patch, loads, step.nodes, np.tile(d, (len(step.nodes), 1)))
    assert _relative(step.nodal_forces, expected_grasp) < 1e-9
    nodes, by_the_hand = forceps.surface_displacement()
    # the whole field: the hand's part plus the needle's loads on the tissue the grasp holds
    needle_alone = np.zeros(3 * mesh.n_nodes)
    needle_alone[node_dofs(needle_nodes)] = needle_forces.reshape(-1)
    needle_held, _ = _dirichlet(patch, needle_alone, step.nodes, np.zeros((len(step.nodes), 3)))
    assert _relative(by_the_hand + needle_held[nodes], expected_u[nodes]) < 1e-9
    hand_alone, _ = _dirichlet(
        patch, np.zeros(3 * mesh.n_nodes), step.nodes, np.tile(d, (len(step.nodes), 1))
    )
    assert _relative(by_the_hand, hand_alone[nodes]) < 1e-9
    assert np.allclose(step.displacement, d)
    assert np.allclose(step.force, step.nodal_forces.sum(axis=0))
    # the same loads given as a force kernel's map and forces (what a FEM step passes): the same grasp
    mapped = np.random.default_rng(3).uniform(0.0, 1.0, size=(9, 6))
    kernel_forces = np.linalg.lstsq(mapped, needle_forces.reshape(-1), rcond=None)[0]
    spread = (mapped @ kernel_forces).reshape(-1, 3)
    by_nodes = forceps.fem_step(0.02, needle_nodes, spread)
    by_kernels = forceps.fem_step(0.02, needle_nodes, spread, (mapped, kernel_forces))
    assert _relative(by_kernels.nodal_forces, by_nodes.nodal_forces) < 1e-12
    # another kernel set's map on the same nodes (the product is kept per map, not per node set)
    doubled = (2.0 * mapped, 0.5 * kernel_forces)
    again = forceps.fem_step(0.03, needle_nodes, spread, doubled)
    assert _relative(again.nodal_forces, by_nodes.nodal_forces) < 1e-12


def test_the_jaws_grasp_the_edge_under_them_and_letting_go_returns_the_tissue_to_rest(patch):
    collision = CollisionMesh(patch.mesh)
    forceps = ForcepsInteraction(patch, collision)
    rest = collision.points.copy()
    jaw = np.array([0.012, 0.005, 0.00075])
    forceps.hold(0.0, jaw, True)
    mesh = patch.mesh
    near = np.linalg.norm(mesh.points[forceps.nodes] - jaw, axis=1)
    corners = np.isin(forceps.nodes, collision.triangles[forceps.triangle])
    assert forceps.nodes.size >= 4 and np.all((near <= 0.75e-3 + 1e-12) | corners)  # the jaws' footprint
    assert not np.isin(forceps.nodes, patch.clamped_nodes).any()
    forceps.hold(0.02, jaw + np.array([0.0, 0.0, 1e-3]), True)
    step = forceps.fem_step(0.02)
    assert step.force[2] > 0  # lifting the edge: the forceps pull it up
    forceps.deform_collision()
    moved = np.linalg.norm(collision.points - rest, axis=1)
    assert moved[forceps.nodes] == pytest.approx(1e-3, rel=1e-9)
    forceps.hold(0.03, jaw + np.array([0.0, 0.0, 1e-3]), False)
    step = forceps.fem_step(0.03)
    assert [event.kind for event in step.events] == ["release_grasp"]
    assert not step.force.any() and not step.displacement.any() and forceps.nodes.size == 0
    forceps.deform_collision()
    assert np.array_equal(collision.points, rest)  # the linear tissue is back at rest


def test_jaws_closed_on_air_or_on_held_tissue_grasp_nothing(patch):
    forceps = ForcepsInteraction(patch, CollisionMesh(patch.mesh))
    forceps.hold(0.0, np.array([0.006, 0.005, 0.004]), True)  # 2.5 mm above the wall
    assert forceps.fem_step(0.0).events == [] and not forceps.grasping
    forceps.hold(0.01, np.array([0.006, 0.005, 0.004]), False)
    assert forceps.fem_step(0.01).events == []
    held_side = np.array([-0.1e-3, 0.005, 0.00075])  # by the held x0 side: every node there is clamped
    forceps = ForcepsInteraction(patch, CollisionMesh(patch.mesh), Forceps(rule="triangle"))
    forceps.hold(0.0, held_side, True)
    assert not forceps.grasping


def test_the_papers_triangle_rule_holds_the_three_corners_of_the_nearest_triangle(patch):
    collision = CollisionMesh(patch.mesh)
    point = np.array([0.0065, 0.0045, 0.0016])
    triangle, on_surface = closest_surface_point(collision, point, 0.5e-3)
    assert on_surface[2] == pytest.approx(0.0015) and on_surface[:2] == pytest.approx(point[:2])
    free = np.ones(patch.mesh.n_nodes, dtype=bool)
    nodes = jaw_nodes(collision, triangle, on_surface, Forceps(rule="triangle"), free)
    assert np.array_equal(nodes, np.sort(collision.triangles[triangle]))


def test_pulling_the_grasped_edge_too_hard_tears_it_out_of_the_jaws(patch):
    forceps = ForcepsInteraction(patch, CollisionMesh(patch.mesh), Forceps(edge_tear_force=0.01))
    jaw = np.array([0.012, 0.005, 0.00075])
    forceps.hold(0.0, jaw, True)
    forceps.fem_step(0.0)
    forceps.hold(0.01, jaw + np.array([0.0, 0.0, 0.3e-3]), True)
    gentle = forceps.fem_step(0.01)
    assert gentle.events == [] and 0 < np.linalg.norm(gentle.force) < 0.01
    forceps.hold(0.02, jaw + np.array([0.0, 0.0, 3e-3]), True)
    torn = forceps.fem_step(0.02)
    assert [event.kind for event in torn.events] == ["edge_torn"]
    assert "tore" in torn.events[0].detail and "mN" in torn.events[0].detail
    assert not forceps.grasping and not torn.force.any()


@pytest.mark.parametrize(
    "change", [{"jaw_width": 0.0}, {"grasp_reach": -1e-3}, {"edge_tear_force": 0.0}, {"rule": "glue"}]
)
def test_forceps_parameters_out_of_range_are_refused_by_name(change):
    with pytest.raises(ForcepsError, match=next(iter(change))):
        Forceps(**change)


coordinate = st.floats(-2.0, 2.0, allow_nan=False)


@settings(max_examples=150, deadline=None)
@given(st.lists(coordinate, min_size=12, max_size=12))
def test_the_closest_point_on_a_triangle_is_on_it_and_no_sampled_point_is_nearer(values):
    corners = np.reshape(values[:9], (1, 3, 3))
    point = np.array(values[9:])
    area = np.linalg.norm(np.cross(corners[0, 1] - corners[0, 0], corners[0, 2] - corners[0, 0]))
    if area < 1e-3:
        return  # near-degenerate triangles: the sampled reference is not fine enough
    nearest = _closest_on_triangles(point, corners)[0]
    u, v = np.meshgrid(np.linspace(0, 1, 61), np.linspace(0, 1, 61))
    inside = u + v <= 1
    samples = (
        corners[0, 0]
        + u[inside, None] * (corners[0, 1] - corners[0, 0])
        + v[inside, None] * (corners[0, 2] - corners[0, 0])
    )
    sampled = np.linalg.norm(samples - point, axis=1).min()
    assert np.linalg.norm(nearest - point) <= sampled + 1e-12
    # on the triangle: its barycentric coordinates are in [0, 1]
    matrix = np.column_stack([corners[0, 1] - corners[0, 0], corners[0, 2] - corners[0, 0]])
    (s, t), *_ = np.linalg.lstsq(matrix, nearest - corners[0, 0], rcond=None)
    assert s >= -1e-9 and t >= -1e-9 and s + t <= 1 + 1e-9
    assert np.allclose(corners[0, 0] + matrix @ [s, t], nearest, atol=1e-9)


def test_a_precomputed_model_grasps_as_the_on_demand_one(patch):
    precomputed = TissueModel(patch.mesh, Material(20e3, 0.45), patch.clamped_nodes)
    precomputed.precompute(use_cache=False)
    held = _edge_nodes(patch)
    d = np.tile([0.1e-3, 0.2e-3, 0.5e-3], (len(held), 1))
    on_demand, ahead = patch.prescribed(held), precomputed.prescribed(held)
    assert _relative(ahead.forces(d), on_demand.forces(d)) < 1e-9
    assert np.array_equal(ahead.surface_nodes, on_demand.surface_nodes)
    assert (
        _relative(
            ahead.surface_displacement(ahead.forces(d)), on_demand.surface_displacement(on_demand.forces(d))
        )
        < 1e-9
    )


def test_a_grasp_prepared_ahead_is_the_grasp_made_on_the_spot(patch):
    """The graphics layer prepares the grasp under the open jaws (only from columns already solved);
    closing them reuses it when the nodes under the jaws are the same, with forces and field equal to
    a grasp built on the spot, and builds afresh when the hand has moved on to other nodes."""
    jaw = np.array([0.012, 0.005, 0.00075])
    lift = np.array([0.0, 0.2e-3, 0.5e-3])
    fresh = ForcepsInteraction(patch, CollisionMesh(patch.mesh))
    fresh.hold(0.0, jaw, True)
    fresh.hold(0.01, jaw + lift, True)
    expected = fresh.fem_step(0.01)
    nodes = fresh.nodes.copy()
    fresh.hold(0.02, jaw, False)
    ahead = ForcepsInteraction(patch, CollisionMesh(patch.mesh))
    ahead.hold(0.0, jaw, False)
    ahead.prepare()
    assert ahead._ready is not None and np.array_equal(ahead._ready[0], nodes)
    prepared = ahead._ready[1]
    ahead.hold(0.0, jaw, True)
    assert ahead._handle is prepared  # reused, not rebuilt
    ahead.hold(0.01, jaw + lift, True)
    step = ahead.fem_step(0.01)
    np.testing.assert_array_equal(step.nodal_forces, expected.nodal_forces)
    np.testing.assert_array_equal(ahead.surface_displacement()[1], fresh_field(patch, jaw, lift))
    ahead.hold(0.02, jaw, False)
    elsewhere = jaw + np.array([-3e-3, 0.0, 0.0])  # the hand moved along the edge: other nodes
    ahead.hold(0.03, elsewhere, True)
    assert ahead._handle is not prepared and not np.array_equal(ahead.nodes, nodes)


def fresh_field(patch, jaw, lift):
    hand = ForcepsInteraction(patch, CollisionMesh(patch.mesh))
    hand.hold(0.0, jaw, True)
    hand.hold(0.01, jaw + lift, True)
    hand.fem_step(0.01)
    return hand.surface_displacement()[1]


def test_nothing_is_prepared_from_columns_not_yet_solved(patch):
    """The graphics layer never solves: with the nodes under the jaws not in the column cache, it
    prepares nothing and the FEM step builds the grasp when the jaws close."""
    model = TissueModel(patch.mesh, Material(20e3, 0.45), patch.clamped_nodes)  # its cache empty
    jaw = np.array([0.012, 0.005, 0.00075])
    hand = ForcepsInteraction(model, CollisionMesh(patch.mesh))
    hand.hold(0.0, jaw, False)
    hand.prepare()
    assert hand._ready is None and hand.model.cached_columns == 0
    hand.hold(0.01, jaw, True)
    assert hand.grasping and hand.model.spot_solved


def test_a_hand_holding_still_leaves_the_collision_mesh_alone(patch):
    """The graphics layer moves the collision mesh only when the grasp or the hand's displacement
    changed since its last frame; a release puts it back at rest once."""
    collision = CollisionMesh(patch.mesh)
    hand = ForcepsInteraction(patch, collision)
    jaw = np.array([0.012, 0.005, 0.00075])
    hand.hold(0.0, jaw, True)
    hand.hold(0.01, jaw + np.array([0.0, 0.0, 0.3e-3]), True)
    hand.fem_step(0.01)
    hand.deform_collision()
    shown = collision.points
    hand.fem_step(0.02)  # the hand has not moved
    hand.deform_collision()
    assert collision.points is shown
    hand.hold(0.03, jaw + np.array([0.0, 0.0, 0.4e-3]), True)
    hand.fem_step(0.03)
    hand.deform_collision()
    assert collision.points is not shown
    assert np.linalg.norm(
        collision.points[hand.nodes] - patch.mesh.points[hand.nodes], axis=1
    ) == pytest.approx(0.4e-3, rel=1e-9)
    hand.hold(0.04, jaw, False)
    hand.fem_step(0.04)
    hand.deform_collision()
    assert np.array_equal(collision.points, patch.mesh.points)


def test_a_needle_entering_square_to_the_everted_edge_is_credited_square(patch):
    """The collision mesh follows the grasp, so a contact on the lifted edge carries the everted
    wall's normal: a needle coming in along it enters at 0 deg, though it is tilted against the wall
    at rest (the entry angle is measured against the tissue where it is)."""
    from sim.collision.mesh import TriangleContact
    from sim.needle.events import entry_angle_deg

    collision = CollisionMesh(patch.mesh)
    hand = ForcepsInteraction(patch, collision)
    jaw = np.array([0.012, 0.005, 0.00075])  # the middle of the wound edge (the free x1 face)
    hand.hold(0.0, jaw, True)
    hand.hold(0.01, jaw + np.array([0.0, 0.0, 0.6e-3]), True)  # lift the edge 0.6 mm
    hand.fem_step(0.01)
    hand.deform_collision()
    # a point on the top face 0.8 mm in from the edge: where a bite beside the held edge goes in
    target = np.array([0.0112, 0.005, 0.0015])
    start, end = target + np.array([0.0, 0.0, 2e-3]), target - np.array([0.0, 0.0, 2e-3])
    found = collision.query(np.array([start, end]))
    top = int(np.argmin(np.abs(found.t - 0.5)))
    triangle = int(found.triangle[top])
    everted = collision.normals[triangle]
    rest_normal = np.cross(*(np.diff(patch.mesh.points[collision.triangles[triangle]], axis=0)))
    rest_normal /= np.linalg.norm(rest_normal) * np.sign(rest_normal[2])
    tilt = entry_angle_deg(-everted, rest_normal)
    assert tilt > 5.0, tilt  # the lifted edge leans well away from the wall at rest
    # the needle comes in square to the everted surface, through that triangle's centre
    centre = collision.corners[triangle].mean(axis=0)
    path = np.array([centre + 1e-3 * everted, centre - 1e-3 * everted])
    hits = collision.query(path)
    k = int(np.flatnonzero(hits.triangle == triangle)[0])
    contact = TriangleContact.from_hit(collision, hits, k, centre)
    assert entry_angle_deg(-everted, contact.normal) == pytest.approx(0.0, abs=1e-6)
    assert entry_angle_deg(-everted, rest_normal) == pytest.approx(tilt)
