import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sim.errors import ModelError
from sim.fem import BiphaseParameters, BiphaseTissue
from tests.conftest import top_centre_triangle


@pytest.fixture(scope="module")
def biphase(cube, tmp_path_factory):
    tissue = BiphaseTissue.build(cube, cube.node_sets["z0"])
    tissue.precompute(cache_dir=tmp_path_factory.mktemp("cache"))
    return tissue


def press(tissue, triangle, strain, speed=0.0, weights=(0.5, 0.3, 0.2), **options):
    depth = 0.01
    d = np.array([0.0, 0.0, -strain * depth])
    contacts = {int(n): w * d for n, w in zip(triangle, weights, strict=True)}
    return tissue.solve(contacts, tool_displacement=d, depth=depth, needle_speed=speed, **options)


def test_soft_phase_below_the_limit(biphase, cube):
    tri = top_centre_triangle(cube)
    below = press(biphase, tri, 0.1)
    assert not below.stiff_phase
    soft_only = biphase.soft.solve(dict(zip(below.contact_nodes.tolist(), below.soft.intended, strict=True)))
    np.testing.assert_allclose(below.reaction_forces, soft_only.reaction_forces, rtol=1e-12)
    assert below.stretch_ratio == pytest.approx(1.1)


def test_continuous_at_the_limit_and_stiffer_above(biphase, cube):
    tri = top_centre_triangle(cube)
    eps = 1e-9
    at = press(biphase, tri, 0.2).net_force[2]
    just_above = press(biphase, tri, 0.2 + eps).net_force[2]
    assert abs(just_above - at) < 1e-6 * abs(at)
    slope_soft = press(biphase, tri, 0.1).net_force[2] / 0.1
    slope_above = (press(biphase, tri, 0.4).net_force[2] - at) / 0.2
    # Above the limit the increment is answered by the stiff phase: E2/E1 = 2 times steeper.
    assert slope_above / slope_soft == pytest.approx(2.0, rel=1e-9)
    displaced = press(biphase, tri, 0.2 + eps, full_field=True).displacement
    np.testing.assert_allclose(displaced, press(biphase, tri, 0.2, full_field=True).displacement, atol=1e-12)


def test_speed_lowers_the_limit_and_stiffens_sooner(biphase, cube):
    tri = top_centre_triangle(cube)
    p = biphase.parameters
    assert p.strain_limit_at(0.0) == pytest.approx(0.2)
    assert p.strain_limit_at(p.critical_speed) == pytest.approx(0.2 * p.limit_floor)
    assert p.strain_limit_at(10 * p.critical_speed) == pytest.approx(0.2 * p.limit_floor)
    slow = press(biphase, tri, 0.15, speed=0.0)
    fast = press(biphase, tri, 0.15, speed=p.critical_speed)
    assert not slow.stiff_phase and fast.stiff_phase
    assert abs(fast.net_force[2]) > abs(slow.net_force[2])


@given(st.floats(0, 0.05), st.floats(0, 0.05))
def test_limit_never_rises_with_speed(a, b):
    p = BiphaseParameters()
    slow, fast = sorted((a, b))
    assert p.strain_limit_at(fast) <= p.strain_limit_at(slow) + 1e-15
    assert p.limit_floor * p.strain_limit <= p.strain_limit_at(fast) <= p.strain_limit


def test_per_tick_contact_matches_solve(biphase, cube):
    tri = top_centre_triangle(cube)
    handle = biphase.contact(tri)
    for strain, speed in ((0.05, 0.0), (0.3, 0.0), (0.1, 0.008)):
        d = np.array([1e-4, 0.0, -strain * handle.depth])
        intended = np.outer([0.5, 0.3, 0.2], d)
        contacts = {int(n): a for n, a in zip(tri, intended, strict=True)}
        expected = biphase.solve(contacts, tool_displacement=d, needle_speed=speed).reaction_forces
        np.testing.assert_allclose(handle.reaction_forces(intended, d, speed), expected, rtol=1e-10)


def test_fields_superimpose_both_phases(biphase, cube):
    tri = top_centre_triangle(cube)
    solution = press(biphase, tri, 0.3, fields=True)
    assert solution.volume_change is not None and solution.von_mises.shape == (cube.n_elements,)
    assert solution.von_mises.max() > press(biphase, tri, 0.3 * 0.999, fields=True).von_mises.max() * 0.99


def test_depth_by_ray_cast(biphase, cube):
    assert biphase.depth_under(top_centre_triangle(cube)) == pytest.approx(0.01, rel=1e-12)


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"strain_limit": 1.5}, r"strain_limit must be in \(0, 1\)"),
        ({"critical_speed": 0.0}, "critical_speed must be positive"),
        ({"limit_floor": 0.0}, "limit_floor"),
        ({"soft_modulus": 50e3}, "stiff_modulus .* must be at least soft_modulus"),
    ],
)
def test_parameter_validation(options, message):
    with pytest.raises(ModelError, match=message):
        BiphaseParameters(**options)


def test_negative_speed_rejected():
    with pytest.raises(ModelError, match="needle_speed must be a non-negative"):
        BiphaseParameters().strain_limit_at(-1.0)


def independent(model, scale):
    """A TissueModel like ``model`` with E scaled by ``scale``, sharing nothing with it."""
    from sim.fem import TissueModel

    return TissueModel(model.mesh, model.material.scaled(scale), model.fixed_dofs // 3)


@settings(max_examples=15, deadline=None)
@given(scale=st.floats(0.1, 10.0), corner=st.integers(0, 10**6), strain=st.floats(0.0, 0.3))
def test_a_scaled_model_shares_the_inverse_exactly(small_box, scale, corner, strain):
    from sim.fem import Material, TissueModel

    base = TissueModel(small_box, Material(20e3, 0.45), small_box.node_sets["z0"])
    shared = TissueModel(small_box, Material(20e3 * scale, 0.45), small_box.node_sets["z0"])
    assert shared.share_inverse_with(base) == pytest.approx(scale, rel=1e-12)
    alone = independent(base, scale)
    assert shared.penalty == pytest.approx(alone.penalty, rel=1e-12)
    triangle = small_box.surface_triangles[corner % len(small_box.surface_triangles)]
    contacts = {int(n): np.array([0.0, 0.0, -strain * 1e-3]) for n in triangle}
    ours = shared.solve(contacts, full_field=True)
    theirs = alone.solve(contacts, full_field=True)
    np.testing.assert_allclose(ours.reaction_forces, theirs.reaction_forces, rtol=1e-8, atol=1e-14)
    np.testing.assert_allclose(ours.displacement, theirs.displacement, rtol=1e-8, atol=1e-15)
    handle, reference = shared.contact(triangle), alone.contact(triangle)
    drive = np.full((3, 3), 1e-4)
    np.testing.assert_allclose(handle.reaction_forces(drive), reference.reaction_forces(drive), rtol=1e-8)
    assert "_stiffness" not in shared.__dict__  # it never assembled, let alone factorised, its own K0


def test_precomputed_stiff_phase_is_the_soft_one_scaled(cube, tmp_path):
    tissue = BiphaseTissue.build(cube, cube.node_sets["z0"])
    soft, stiff = tissue.precompute(cache_dir=tmp_path)
    alone = independent(tissue.soft, tissue.parameters.stiff_modulus / tissue.parameters.soft_modulus)
    reference = alone.precompute(use_cache=False)
    np.testing.assert_allclose(
        stiff.matrix, reference.matrix, rtol=1e-9, atol=1e-12 * np.abs(reference.matrix).max()
    )
    np.testing.assert_array_equal(stiff.matrix, soft.matrix / 2.0)  # E2 = 2 E1: scaling by 2 is exact
    assert "derived" in stiff.seconds


def test_models_that_are_not_multiples_share_nothing(small_box):
    from sim.fem import Material, TissueModel

    base = TissueModel(small_box, Material(20e3, 0.45), small_box.node_sets["z0"])
    other_nu = TissueModel(small_box, Material(40e3, 0.40), small_box.node_sets["z0"])
    other_support = TissueModel(small_box, Material(40e3, 0.45), small_box.node_sets["z1"])
    explicit = TissueModel(small_box, Material(40e3, 0.45), small_box.node_sets["z0"], penalty=1e6)
    for model in (other_nu, other_support, explicit, base):
        assert model.share_inverse_with(base) is None
        assert model._inverse_of is None


@settings(max_examples=10, deadline=None)
@given(
    strain=st.floats(0.0, 0.6),
    speed=st.floats(0.0, 0.05),
    weights=st.sampled_from([(1, 0, 0), (0.5, 0.3, 0.2)]),
)
def test_replayed_fields_of_the_shared_inverse_equal_independent_phases(small_box, strain, speed, weights):
    from sim.fem import Material, TissueModel
    from sim.fem.fields import TissueFieldReplay

    p = BiphaseParameters()
    fixed = small_box.node_sets["z0"]
    shared = BiphaseTissue.build(small_box, fixed, p)
    soft = TissueModel(small_box, Material(p.soft_modulus, p.poisson_ratio), fixed)
    stiff = TissueModel(small_box, Material(p.stiff_modulus, p.poisson_ratio), fixed)
    stiff.penalty  # noqa: B018 - a model whose penalty is already set is never linked: independent phases
    alone = BiphaseTissue(soft, stiff, p)
    assert shared.stiff._inverse_of is not None and alone.stiff._inverse_of is None
    triangle = top_centre_triangle(small_box)
    drive = np.outer(weights, [0.0, 0.0, -strain * 0.003])
    ours = TissueFieldReplay(shared).state(triangle, drive, speed)
    theirs = TissueFieldReplay(alone).state(triangle, drive, speed)
    np.testing.assert_allclose(ours[0], theirs[0], rtol=1e-9, atol=1e-18)
    np.testing.assert_allclose(ours[1], theirs[1], rtol=1e-8, atol=1e-9)


@settings(max_examples=10, deadline=None)
@given(corner=st.integers(0, 10**6), precomputed=st.booleans())
def test_the_stiff_contact_derived_from_the_soft_one_equals_an_independent_stiff_model(
    small_box, corner, precomputed, tmp_path_factory
):
    """BiphaseTissue.contact scales the soft handle for the stiff phase; an independent stiff
    TissueModel (own K0, own factorisation) must give the same forces and displacements."""
    tissue = BiphaseTissue.build(small_box, small_box.node_sets["z0"])
    scale = tissue.parameters.stiff_modulus / tissue.parameters.soft_modulus
    alone = independent(tissue.soft, scale)
    if precomputed:
        tissue.precompute(cache_dir=tmp_path_factory.mktemp("cache"))
        alone.precompute(use_cache=False)
    top = small_box.points[:, 2].max()  # where a needle touches: depth under the top face is defined
    faces = [t for t in small_box.surface_triangles if np.all(small_box.points[t, 2] == top)]
    triangle = faces[corner % len(faces)]
    ours, theirs = tissue.contact(triangle).stiff, alone.contact(triangle)
    drive = np.linspace(-1e-4, 1e-4, 9).reshape(3, 3)
    reactions = theirs.reaction_forces(drive)
    np.testing.assert_allclose(ours.reaction_forces(drive), reactions, rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(
        ours.surface_displacement(reactions), theirs.surface_displacement(reactions), rtol=1e-8, atol=1e-15
    )
    assert ours.penalty == pytest.approx(theirs.penalty, rel=1e-12)


def test_region_parameters_give_each_region_its_moduli_and_keep_one_factorisation():
    """A calcified plaque four times stiffer in both phases: its elements carry the plaque's moduli,
    the stiff phase is still the soft one scaled (shared inverse); a region the mesh lacks is named."""
    from sim.mesh import Calcification, vessel_mesh

    mesh = vessel_mesh(
        arc_deg=90.0,
        circumferential_divisions=6,
        radial_divisions=2,
        axial_divisions=4,
        length=0.004,
        calcification=Calcification((0.0, 45.0), (0.0, 0.004), (0, 1)),
    )
    wall = BiphaseParameters(soft_modulus=300e3, stiff_modulus=6e6)
    plaque = BiphaseParameters(soft_modulus=1.2e6, stiff_modulus=24e6)
    fixed = mesh.node_sets["end0"]
    tissue = BiphaseTissue.build(mesh, fixed, wall, region_parameters={"calcified": plaque})
    calcified = mesh.regions == {n: r for r, n in mesh.region_names.items()}["calcified"]
    assert 0 < calcified.sum() < len(calcified)
    ratio = tissue.soft.lame[1][calcified] / tissue.soft.lame[1][~calcified].max()
    assert np.allclose(ratio, 4.0)
    assert tissue.stiff.inverse_source == (tissue.soft, pytest.approx(20.0))
    with pytest.raises(ModelError, match="region\\(s\\) plaque, which the mesh does not have"):
        BiphaseTissue.build(mesh, fixed, wall, region_parameters={"plaque": plaque})


def test_one_phase_and_the_biphase_pair_are_both_tissues(small_box):
    """Issue 24: the Tissue protocol replaces the isinstance(..., BiphaseTissue) branches: the runtime
    asks a tissue for its models, its base model and its biphase law."""
    from sim.fem import Tissue

    pair = BiphaseTissue.build(small_box, small_box.node_sets["z0"])
    single = pair.soft
    assert isinstance(pair, Tissue) and isinstance(single, Tissue)
    assert pair.models == (pair.soft, pair.stiff) and pair.base is pair.soft
    assert pair.biphase is pair.parameters
    assert single.models == (single,) and single.base is single and single.biphase is None
    top = small_box.node_sets["z1"][:3]
    assert single.depth_under(top) == pair.depth_under(top) > 0  # cast in the base model, the same way
