"""Continuous collision detection of the needle's swept path (issue 43, item 1): a needle cannot pass
through a wall between two FEM steps however fast it moves, and its contact starts where and when it
met the surface."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sessions.tasks import task_preset, task_spec, tissue_for
from sim.collision import _near as near
from sim.collision.mesh import CollisionMesh
from sim.fem import Material, TissueModel
from sim.mesh import box_mesh
from sim.needle import Needle, Pose, rotation_aligning
from sim.needle.interaction import NeedleInteraction
from sim.needle.sweep import KnownBalls, first_touch

THICKNESS = 0.0015


@pytest.fixture(scope="module")
def slab():
    """A 1.5 mm wall, 10 x 10 mm (top face at z = 1.5 mm), lying on a firm bed (its underside held)."""
    mesh = box_mesh((0.01, 0.01, THICKNESS), (8, 8, 3))
    fixed = mesh.node_sets["z0"]  # on a firm bed, as a patch on the bench
    model = TissueModel(mesh, Material(300e3, 0.45), fixed)
    model.precompute(use_cache=False)
    return model


@pytest.fixture(scope="module")
def collision(slab):
    return CollisionMesh(slab.mesh)


DOWN = rotation_aligning([1, 0, 0], [0, 0, -1])  # a straight needle's tip pointing down


def straight_needle_at(tip, needle, rotation=DOWN):
    """World vertices of ``needle`` with its tip at ``tip``."""
    pose = Pose(np.asarray(tip) - rotation @ needle.vertices[0], rotation)
    return needle.world_vertices(pose)


def test_a_tip_that_jumps_through_the_whole_wall_in_one_step_meets_its_top_face(collision):
    """Before: 30 Hz detection on the tip segment only, so above ~18 mm/s the tip skipped the surface
    (r = 6.4 mm to 1.6 mm straight through a 1.5 mm wall, 0 N). Here the tip goes from 1 mm above the
    wall to 0.5 mm below it in one step: the sweep finds the top face, a third of the way."""
    needle = Needle.straight(0.01)
    before = straight_needle_at([0.005, 0.0047, THICKNESS + 1e-3], needle)
    after = straight_needle_at([0.005, 0.0047, -0.5e-3], needle)
    assert len(collision.query(before)) == 0  # neither pose alone says where the wall was met
    touch = first_touch(collision, before, after)
    assert touch is not None and touch.at_tip and touch.entering
    assert touch.fraction == pytest.approx(1.0 / 3.0, abs=1e-12)
    np.testing.assert_allclose(touch.point, [0.005, 0.0047, THICKNESS], atol=1e-12)
    np.testing.assert_allclose(collision.normals[touch.triangle], [0, 0, 1], atol=1e-12)


def test_a_body_swept_across_the_walls_edge_is_found_though_no_vertex_crosses(collision):
    """A one-segment needle lying across the wall (both ends beyond it) swept sideways into its side:
    no vertex's path and neither pose's polyline crosses a face the other did not; the surface's edges
    through the swept quadrilateral do."""
    needle = Needle.straight(0.014, segments=1)
    along_y = rotation_aligning([1, 0, 0], [0, 1, 0])
    z = 0.5 * THICKNESS + 1e-5  # not on a mesh node's level

    def at(x):
        middle = 0.5 * (needle.vertices[0] + needle.vertices[1])
        pose = Pose(np.array([x, 0.005, z]) - along_y @ middle, along_y)
        return needle.world_vertices(pose)

    before, after = at(0.0104), at(0.0096)  # across the x = 10 mm face, 0.4 mm either side
    touch = first_touch(collision, before, after)
    assert touch is not None and touch.entering
    assert touch.fraction == pytest.approx(0.5, abs=1e-9)
    np.testing.assert_allclose(collision.normals[touch.triangle], [1, 0, 0], atol=1e-12)
    assert touch.point[0] == pytest.approx(0.01, abs=1e-12)


def test_a_needle_drawn_out_of_the_wall_meets_nothing(collision):
    needle = Needle.straight(0.01)
    inside = straight_needle_at([0.005, 0.0047, 0.5e-3], needle)
    outside = straight_needle_at([0.005, 0.0047, THICKNESS + 11e-3], needle)
    assert first_touch(collision, inside, outside) is None


@settings(max_examples=60, deadline=None)
@given(
    x=st.floats(0.002, 0.008),
    y=st.floats(0.002, 0.008),
    above=st.floats(1e-6, 1e-3),
    speed=st.floats(1e-3, 0.5),  # m/s: up to 500 mm/s
    dt=st.sampled_from([1e-3, 2e-3, 5e-3]),  # 1000, 500 and 200 Hz FEM
)
def test_the_first_crossing_is_found_at_any_speed_where_it_happened(collision, x, y, above, speed, dt):
    """A tip moving straight down from ``above`` the wall at up to 500 mm/s: whenever it reaches the
    surface within the step, the sweep reports the analytic crossing (fraction and point)."""
    needle = Needle.straight(0.01)
    top = THICKNESS + above
    step = speed * dt
    before = straight_needle_at([x, y, top], needle)
    after = straight_needle_at([x, y, top - step], needle)
    touch = first_touch(collision, before, after)
    if step <= above * (1 + 1e-9):  # short of the surface, or ending on it (not into the wall)
        assert touch is None or step >= above * (1 - 1e-9)
        return
    assert touch is not None and touch.at_tip and touch.entering
    assert touch.fraction == pytest.approx(above / step, abs=1e-9)
    np.testing.assert_allclose(touch.point, [x, y, THICKNESS], atol=1e-12)


FEM_DT = 0.002


def drive(interaction, tip_at, duration, fem_dt=FEM_DT):
    """FEM steps of a grasped straight needle whose tip follows ``tip_at(t)`` (graphics every 33 ms)."""
    events, forces, states = [], [], []
    for k in range(round(duration / fem_dt) + 1):
        t = k * fem_dt
        tip = tip_at(t)
        interaction.hold(t, Pose(tip - DOWN @ interaction.needle.vertices[0], DOWN), True)
        if k % 16 == 0:
            events += interaction.graphics_step(t)
        step = interaction.fem_step(t)
        events += step.events
        forces.append(step.needle_force.copy())
        states.append(interaction.state)
    return events, np.array(forces), states


@pytest.fixture(scope="module")
def wall_stitch():
    return tissue_for(task_spec("wall-stitch"), None)


@pytest.mark.parametrize("speed", [0.005, 0.05, 0.5])
def test_a_fast_needle_is_felt_from_where_it_met_the_wall_and_pierces(wall_stitch, speed):
    """The wall-stitch task's wall at 5, 50 and 500 mm/s: the contact starts at the moment and point the
    tip met the surface, the first step's force is that of a needle pressed statically to the depth
    reached since (no jump from a late detection), the needle pierces at a felt force, and it is never
    free with its tip in the wall."""
    spec = task_spec("wall-stitch")
    forces = task_preset(task_spec("wall-stitch")).forces
    entry, top = np.asarray(spec.entry), spec.entry[2]
    interaction = NeedleInteraction(wall_stitch, Needle.straight(0.01), forces=forces)
    start = top + 1.3e-3
    duration = 1.3e-3 / speed + 0.004 / speed
    events, force, states = drive(
        interaction, lambda t: entry + np.array([0, 0, 1.3e-3 - speed * t]), duration
    )
    kinds = [e.kind for e in events]
    assert "implausible_hit" not in kinds
    assert kinds[:2] == ["contact_start", "pierce"]
    assert events[0].time == pytest.approx(1.3e-3 / speed, abs=1e-9)
    assert 300 <= float(events[1].detail.split()[2]) <= 6000  # "normal force X mN"
    first = next(k for k, s in enumerate(states) if s == "contact")
    indentation = speed * (first * FEM_DT) - 1.3e-3
    assert 0.0 <= indentation <= speed * FEM_DT + 1e-12
    # the same needle set on the surface and pressed in to that depth at the same speed in one step
    static = NeedleInteraction(wall_stitch, Needle.straight(0.01), forces=forces)
    for t, depth in ((0.0, 0.0), (indentation / speed, indentation)):
        tip = entry - np.array([0, 0, depth])
        static.hold(t, Pose(tip - DOWN @ static.needle.vertices[0], DOWN), True)
        pressed = static.fem_step(t).needle_force
    np.testing.assert_allclose(force[first], pressed, rtol=1e-9, atol=1e-12)
    tip_height = [start - speed * k * FEM_DT for k in range(len(states))]
    inside = [s for s, z in zip(states, tip_height, strict=True) if top - THICKNESS < z < top - 1e-9]
    assert inside and "free" not in inside


@settings(max_examples=200, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    vertices=st.integers(2, 8),
    step=st.floats(0.0, 2e-3),
    pad=st.floats(-1e-3, 2e-3),
    poison=st.booleans(),
)
def test_the_compiled_swept_box_test_is_the_numpy_one(seed, vertices, step, pad, poison):
    """sim.collision._near.swept_inside (whether a step's swept boxes stay inside the last near-box
    query's padded balls, so its answer holds) says what the NumPy test said; a NaN says no."""
    rng = np.random.default_rng(seed)
    before = rng.normal(size=(vertices, 3)) * 1e-3
    after = before + rng.normal(size=(vertices, 3)) * step
    if poison:
        after[int(rng.integers(vertices)), int(rng.integers(3))] = np.nan
    centres = rng.normal(size=(vertices - 1, 3)) * 1e-4 + 0.5 * (before[1:] + before[:-1])
    radii = np.abs(rng.normal(size=vertices - 1)) * 1e-3 + pad
    moved = float(rng.uniform(0.0, 1e-4))
    lower = np.minimum(np.minimum(before[1:], before[:-1]), np.minimum(after[1:], after[:-1]))
    upper = np.maximum(np.maximum(before[1:], before[:-1]), np.maximum(after[1:], after[:-1]))
    own = 0.5 * np.sqrt(np.einsum("ij,ij->i", upper - lower, upper - lower)) + moved
    shift = np.sqrt(np.einsum("ij,ij->i", 0.5 * (lower + upper) - centres, 0.5 * (lower + upper) - centres))
    expected = bool(np.all(shift + own <= radii))
    assert near.swept_inside(before, after, moved, centres, radii) == expected


@settings(max_examples=200, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), listed=st.integers(0, 12), balls=st.integers(0, 4))
def test_the_compiled_known_corners_test_is_the_numpy_one(seed, listed, balls):
    """sim.collision._near.all_within (every corner of the triangles within reach is one the needle
    already accounts for) says what KnownBalls says of those corners point by point."""
    rng = np.random.default_rng(seed)
    corners = rng.normal(size=(20, 3, 3)) * 1e-3
    triangles = rng.integers(0, 20, size=listed)
    known = KnownBalls(rng.normal(size=(balls, 3)) * 5e-4, rng.uniform(5e-4, 4e-3, size=balls))
    expected = bool(known(corners[triangles].reshape(-1, 3)).all())
    assert near.all_within(corners, triangles, known.centres, known.radii**2) == expected


def test_the_compiled_collision_answers_refuse_what_does_not_fit():
    box = np.zeros((3, 3))
    with pytest.raises(ValueError, match=r"centres \(V - 1, 3\)"):
        near.swept_inside(box, box, 0.0, np.zeros((3, 3)), np.zeros(2))
    with pytest.raises(ValueError, match="triangle id 20 is not one of the 20 triangles"):
        near.all_within(np.zeros((20, 3, 3)), np.array([3, 20]), np.zeros((1, 3)), np.ones(1))
    with pytest.raises(TypeError, match="triangles must be int64"):
        near.all_within(np.zeros((20, 3, 3)), np.array([3.0]), np.zeros((1, 3)), np.ones(1))
