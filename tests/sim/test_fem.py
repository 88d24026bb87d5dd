import numpy as np
import pytest
import scipy.linalg
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from sim.errors import MaterialError, ModelError
from sim.fem import Material, PoissonRatioWarning, TissueModel
from sim.fem.inverse.condensation import node_dofs
from sim.mesh import box_mesh, vessel_mesh
from sim.mesh.tetmesh import TetMesh
from tests.conftest import top_centre_triangle


def direct_penalty_solve(model: TissueModel, contacts: dict):
    """Independent reference: assemble the full penalised system and solve it with SuperLU.

    Reactions come from the system's own identity R = (K0 u)_J (no cancellation).
    """
    k0 = model.penalised_stiffness().tolil()
    rhs = np.zeros(k0.shape[0])
    c = model.penalty
    for node, a in contacts.items():
        for axis in range(3):
            k0[3 * node + axis, 3 * node + axis] += c
            rhs[3 * node + axis] = c * a[axis]
    u = spla.spsolve(k0.tocsc(), rhs)
    reactions = (model.penalised_stiffness() @ u)[node_dofs(np.array(list(contacts)))]
    return u.reshape(-1, 3), reactions.reshape(-1, 3)


def relative_error(a, b):
    return np.abs(np.asarray(a) - np.asarray(b)).max() / np.abs(b).max()


# -- materials -------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("e", "nu", "message"),
    [
        (0.0, 0.3, "youngs_modulus must be a positive"),
        (-5.0, 0.3, "youngs_modulus"),
        (float("nan"), 0.3, "youngs_modulus"),
        (1e3, 0.5, r"poisson_ratio must satisfy 0 <= nu < 0.5; got 0.5"),
        (1e3, -0.1, "poisson_ratio"),
        (1e3, float("inf"), "poisson_ratio"),
    ],
)
def test_material_validation(e, nu, message):
    with pytest.raises(MaterialError, match=message):
        Material(e, nu)


def test_poisson_above_paper_limit_warns():
    with pytest.warns(PoissonRatioWarning, match="above 0.47"):
        Material(20e3, 0.49)


def test_missing_region_material_is_named():
    mesh = vessel_mesh(arc_deg=60, circumferential_divisions=4, axial_divisions=3)
    with pytest.raises(MaterialError, match=r"no material for mesh region\(s\) 2 \(adventitia\)"):
        TissueModel(mesh, {"intima": Material(1e4), "media": Material(2e4)}, mesh.node_sets["end0"])


# -- stiffness ----------------------------------------------------------------------------
def explicit_element_stiffness(points, material):
    """B^T D B V built the textbook way (Voigt notation), independent of the einsum form."""
    # N_a(x) = c_a0 + c_a . x with N_a(p_b) = delta_ab: coefficients are columns of inv([1 p]).
    grads = np.linalg.inv(np.column_stack([np.ones(4), points]))[1:].T
    b = np.zeros((6, 12))
    for a in range(4):
        gx, gy, gz = grads[a]
        b[:, 3 * a : 3 * a + 3] = [[gx, 0, 0], [0, gy, 0], [0, 0, gz], [gy, gx, 0], [0, gz, gy], [gz, 0, gx]]
    lam, mu = material.lame_lambda, material.shear_modulus
    d = np.zeros((6, 6))
    d[:3, :3] = lam
    d[np.arange(3), np.arange(3)] += 2 * mu
    d[3:, 3:] = mu * np.eye(3)
    volume = np.linalg.det(points[1:] - points[0]) / 6
    return volume * b.T @ d @ b


def test_element_stiffness_matches_textbook_form():
    rng = np.random.default_rng(7)
    points = rng.normal(size=(4, 3)) * 1e-3
    if np.linalg.det(points[1:] - points[0]) < 0:
        points[[2, 3]] = points[[3, 2]]
    material = Material(35e3, 0.42)
    model = TissueModel(TetMesh(points, [[0, 1, 2, 3]]), material, [0, 1, 2])
    np.testing.assert_allclose(
        model.stiffness_matrix().toarray(),
        explicit_element_stiffness(points, material),
        rtol=1e-12,
        atol=1e-12 * 35e3 * 1e-3,
    )


def test_stiffness_symmetric_with_six_rigid_modes(small_box):
    model = TissueModel(small_box, Material(20e3, 0.45), small_box.node_sets["z0"])
    k = model.stiffness_matrix()
    assert abs(k - k.T).max() <= 1e-12 * abs(k).max()
    x = small_box.points
    modes = [np.tile(np.eye(3)[i], (len(x), 1)) for i in range(3)]
    modes += [np.cross(np.eye(3)[i], x) for i in range(3)]
    for mode in modes:
        assert np.abs(k @ mode.ravel()).max() <= 1e-9 * abs(k).max() * np.abs(mode).max()
    eigenvalues = np.linalg.eigvalsh(k.toarray())
    scale = eigenvalues.max()
    assert np.sum(np.abs(eigenvalues) < 1e-10 * scale) == 6
    assert eigenvalues.min() > -1e-10 * scale
    assert np.linalg.eigvalsh(model.penalised_stiffness().toarray()).min() > 0


def test_assembly_reuses_pattern_for_new_materials(small_box):
    soft = TissueModel(small_box, Material(20e3, 0.45), small_box.node_sets["z0"])
    stiff = TissueModel(small_box, Material(40e3, 0.45), small_box.node_sets["z0"])
    np.testing.assert_allclose(
        stiff.stiffness_matrix().toarray(), 2 * soft.stiffness_matrix().toarray(), rtol=1e-12
    )


def test_patch_test_linear_field_reproduced_inside():
    mesh = box_mesh(0.01, 4)
    rng = np.random.default_rng(3)
    interior = np.setdiff1d(np.arange(mesh.n_nodes), mesh.surface_nodes)
    points = mesh.points.copy()
    points[interior] += rng.uniform(-4e-4, 4e-4, size=(len(interior), 3))  # distorted but valid
    mesh = mesh.with_points(points)
    k = TissueModel(mesh, Material(30e3, 0.4), mesh.node_sets["z0"]).stiffness_matrix().tocsr()
    gradient = np.array([[1e-2, 2e-3, -3e-3], [0.0, -5e-3, 1e-3], [4e-3, 0.0, 2e-2]])
    exact = mesh.points @ gradient.T + [1e-4, -2e-4, 5e-5]
    boundary = node_dofs(mesh.surface_nodes)
    inside = node_dofs(interior)
    u_inside = spla.spsolve(k[inside][:, inside].tocsc(), -k[inside][:, boundary] @ exact.ravel()[boundary])
    np.testing.assert_allclose(u_inside, exact.ravel()[inside], rtol=0, atol=1e-12 * np.abs(exact).max())


def roller_box(material, size=(0.004, 0.003, 0.01), divisions=(2, 2, 5)):
    mesh = box_mesh(size, divisions)
    sets = mesh.node_sets
    rollers = np.concatenate([3 * sets["z0"] + 2, 3 * sets["x0"], 3 * sets["y0"] + 1])
    return mesh, rollers


def test_uniaxial_stress_with_poisson_contraction():
    material = Material(25e3, 0.3)
    mesh, rollers = roller_box(material)
    model = TissueModel(mesh, material, fixed_dofs=rollers)
    width, depth, length = 0.004, 0.003, 0.01
    traction = 500.0  # Pa, pulling the top face up
    force = np.zeros(3 * mesh.n_nodes)
    top = mesh.surface_triangles[np.all(np.isin(mesh.surface_triangles, mesh.node_sets["z1"]), axis=1)]
    areas = 0.5 * np.linalg.norm(
        np.cross(
            mesh.points[top[:, 1]] - mesh.points[top[:, 0]], mesh.points[top[:, 2]] - mesh.points[top[:, 0]]
        ),
        axis=1,
    )
    np.add.at(force, 3 * top.ravel() + 2, np.repeat(traction * areas / 3, 3))
    u = model._factor(force).reshape(-1, 3)
    strain = traction / material.youngs_modulus
    penalty_error = 1e3 / 1e5  # ~ stiffness/penalty, documented default factor
    np.testing.assert_allclose(u[mesh.node_sets["z1"], 2], strain * length, rtol=penalty_error)
    np.testing.assert_allclose(u[mesh.node_sets["x1"], 0], -0.3 * strain * width, rtol=penalty_error)
    np.testing.assert_allclose(u[mesh.node_sets["y1"], 1], -0.3 * strain * depth, rtol=penalty_error)
    fields = model.element_fields(u)
    np.testing.assert_allclose(fields["von_mises"], traction, rtol=1e-3)


def test_uniaxial_reaction_equals_e_a_delta_over_l():
    material = Material(20e3, 0.0)  # nu = 0: driving all dofs of the top face is uniaxial
    mesh, rollers = roller_box(material)
    top = mesh.node_sets["z1"]
    model = TissueModel(mesh, material, fixed_dofs=rollers, contact_nodes=top)
    model.precompute(use_cache=False)
    delta = 1e-4
    solution = model.solve({int(n): (0.0, 0.0, -delta) for n in top})
    expected = 20e3 * 0.004 * 0.003 * delta / 0.01
    assert solution.net_force[2] == pytest.approx(-expected, rel=1e-4)
    assert np.abs(solution.net_force[:2]).max() < 1e-6 * expected


def test_two_materials_in_series():
    mesh = box_mesh((0.003, 0.003, 0.01), (2, 2, 6))
    upper = mesh.points[mesh.tets].mean(axis=1)[:, 2] > 0.005
    mesh = TetMesh(mesh.points, mesh.tets, upper.astype(int), {0: "media", 1: "calcified"}, mesh.node_sets)
    sets = mesh.node_sets
    rollers = np.concatenate([3 * sets["z0"] + 2, 3 * sets["x0"], 3 * sets["y0"] + 1])
    e_lower, e_upper = 20e3, 80e3
    model = TissueModel(
        mesh,
        {"media": Material(e_lower, 0.0), "calcified": Material(e_upper, 0.0)},
        fixed_dofs=rollers,
        contact_nodes=sets["z1"],
    )
    delta = 2e-4
    force = model.solve({int(n): (0, 0, -delta) for n in sets["z1"]}).net_force[2]
    series_stiffness = 0.003 * 0.003 / (0.005 / e_lower + 0.005 / e_upper)
    assert force == pytest.approx(-series_stiffness * delta, rel=1e-4)


# -- penalty-condensation ------------------------------------------------------------------
def contact_sets(mesh):
    tri = top_centre_triangle(mesh)
    far = mesh.surface_triangles[np.argmax(mesh.points[mesh.surface_triangles].mean(axis=1) @ [1, 1, 0.1])]
    d = np.array([2e-4, -1e-4, -8e-4])
    single = {int(tri[0]): d}
    triangle = {int(n): w * d for n, w in zip(tri, (0.5, 0.3, 0.2), strict=True)}
    two_hands = dict(triangle)
    two_hands.update({int(n): np.array([-3e-4, 0, 1e-4]) for n in far})
    return {"single": single, "triangle": triangle, "two_hands": two_hands}


@pytest.mark.parametrize("case", ["single", "triangle", "two_hands"])
@pytest.mark.parametrize("mode", ["precomputed", "on_demand"])
def test_condensation_equals_direct_sparse_solve(cube, cube_model, case, mode):
    model = (
        cube_model if mode == "precomputed" else TissueModel(cube, Material(20e3, 0.45), cube.node_sets["z0"])
    )
    contacts = contact_sets(cube)[case]
    u_direct, r_direct = direct_penalty_solve(model, contacts)
    solution = model.solve(contacts)
    assert relative_error(solution.reaction_forces, r_direct) < 1e-10
    assert relative_error(solution.displacement, u_direct[solution.displacement_nodes]) < 1e-10
    full = model.solve(contacts, full_field=True)
    assert relative_error(full.displacement, u_direct) < 1e-10
    if case == "single" and mode == "precomputed":
        fields = model.solve(contacts, fields=True)
        ((node, intended),) = contacts.items()
        assert cube.points[node, 2] == 0.01  # on the top face: 10 mm of tissue below
        assert fields.stretch_ratio == pytest.approx(1 + np.linalg.norm(intended) / 0.01)
        assert fields.element_strain.shape == (cube.n_elements, 3, 3)
        np.testing.assert_allclose(fields.element_strain, np.swapaxes(fields.element_strain, 1, 2))


def test_precomputed_model_serves_non_candidate_nodes_on_demand(cube):
    """A contact set mixing precomputed candidates and other surface nodes is still exact."""
    top = cube.node_sets["z1"]
    model = TissueModel(cube, Material(20e3, 0.45), cube.node_sets["z0"], contact_nodes=top)
    model.precompute(use_cache=False)
    side = int(np.setdiff1d(cube.node_sets["x1"], np.concatenate([top, cube.node_sets["z0"]]))[0])
    contacts = {
        int(top[10]): np.array([0, 0, -3e-4]),
        side: np.array([-2e-4, 1e-4, 0]),
        int(top[40]): np.array([1e-4, 0, -1e-4]),
    }
    _, r_direct = direct_penalty_solve(model, contacts)
    solution = model.solve(contacts)
    assert relative_error(solution.reaction_forces, r_direct) < 1e-10
    handle = model.contact(list(contacts))
    np.testing.assert_allclose(
        handle.reaction_forces(np.array(list(contacts.values()))), solution.reaction_forces, rtol=1e-10
    )


def test_condensation_on_vessel_wall_with_wound():
    from sim.mesh import Wound

    mesh = vessel_mesh(
        arc_deg=90, circumferential_divisions=10, axial_divisions=8, wound=Wound(0, 0.005, 0.015)
    )
    fixed = np.concatenate([mesh.node_sets[s] for s in ("end0", "end1", "side0", "side1")])
    model = TissueModel(
        mesh, {"intima": Material(15e3), "media": Material(30e3), "adventitia": Material(20e3)}, fixed
    )
    model.precompute(use_cache=False)
    edge = mesh.node_sets["wound_a"][
        mesh.points[mesh.node_sets["wound_a"], 2].argsort()[len(mesh.node_sets["wound_a"]) // 2]
    ]
    contacts = {int(edge): np.array([0, 3e-4, 0]), int(mesh.node_sets["outer"][40]): np.array([-2e-4, 0, 0])}
    _u_direct, r_direct = direct_penalty_solve(model, contacts)
    solution = model.solve(contacts)
    assert relative_error(solution.reaction_forces, r_direct) < 1e-10


def test_fast_composite_equals_papers_per_node_inversion(small_box):
    """The paper: for each node, add C, invert the whole matrix, keep its 3 columns (surface rows)."""
    model = TissueModel(small_box, Material(20e3, 0.45), small_box.node_sets["z0"])
    model.precompute(use_cache=False)
    fast = model.composite_matrix()
    k0 = model.penalised_stiffness().toarray()
    rows = node_dofs(model.contact_nodes)
    for j, node in enumerate(model.contact_nodes):
        dofs = node_dofs(np.array([node]))
        penalised = k0.copy()
        penalised[dofs, dofs] += model.penalty
        inverse = scipy.linalg.inv(penalised)
        np.testing.assert_allclose(
            fast[:, 3 * j : 3 * j + 3],
            inverse[np.ix_(rows, dofs)],
            rtol=1e-9,
            atol=1e-12 * np.abs(inverse).max(),
        )


def test_trailing_factor_is_the_schur_complement(small_box):
    from sim.fem.inverse.condensation import condensed_inverse, condensed_inverse_multi_rhs, trailing_cholesky

    model = TissueModel(small_box, Material(20e3, 0.45), small_box.node_sets["z0"])
    k0 = model.penalised_stiffness()
    kept = node_dofs(model.contact_nodes)
    dense = k0.toarray()
    inner = np.setdiff1d(np.arange(dense.shape[0]), kept)
    schur = dense[np.ix_(kept, kept)] - dense[np.ix_(kept, inner)] @ np.linalg.solve(
        dense[np.ix_(inner, inner)], dense[np.ix_(inner, kept)]
    )
    lower = trailing_cholesky(k0, kept)
    np.testing.assert_allclose(lower @ lower.T, schur, rtol=1e-10, atol=1e-10 * np.abs(schur).max())
    np.testing.assert_allclose(
        condensed_inverse(k0, kept),
        condensed_inverse_multi_rhs(k0, kept),
        rtol=1e-9,
        atol=1e-12 * np.abs(np.linalg.inv(schur)).max(),
    )


def test_superposition_matches_exact_only_for_independent_contacts(cube, cube_model):
    sets = contact_sets(cube)
    single = sets["single"]
    np.testing.assert_allclose(
        cube_model.solve(single, method="superposition").reaction_forces,
        cube_model.solve(single).reaction_forces,
        rtol=1e-12,
    )
    near = sets["triangle"]
    exact = cube_model.solve(near).net_force
    plain = cube_model.solve(near, method="superposition").net_force
    assert np.linalg.norm(plain - exact) > 0.2 * np.linalg.norm(exact)  # neighbours interact strongly


def test_contact_handle_matches_solve(cube, cube_model):
    contacts = contact_sets(cube)["triangle"]
    handle = cube_model.contact(list(contacts))
    intended = np.array(list(contacts.values()))
    solution = cube_model.solve(contacts)
    reactions = handle.reaction_forces(intended)
    np.testing.assert_allclose(reactions, solution.reaction_forces, rtol=1e-12)
    np.testing.assert_allclose(
        handle.surface_displacement(reactions), solution.displacement, rtol=1e-10, atol=1e-18
    )


def test_whole_field_handle_matches_the_full_field_solve(cube, cube_model):
    """The display's handle: the same reactions and the same displacement at every node as a sparse
    solve of the full field, for two different pushes through the one handle."""
    contacts = contact_sets(cube)["triangle"]
    handle = cube_model.field_contact(list(contacts))
    assert handle.surface_nodes.tolist() == list(range(cube.n_nodes))
    for scale in (1.0, -0.37):
        pushed = {node: scale * np.asarray(a) for node, a in contacts.items()}
        solution = cube_model.solve(pushed, full_field=True)
        reactions = handle.reaction_forces(np.array(list(pushed.values())))
        np.testing.assert_allclose(reactions, solution.reaction_forces, rtol=1e-10)
        field = handle.surface_displacement(reactions)
        scale_of_field = np.abs(solution.displacement).max()
        np.testing.assert_allclose(field, solution.displacement, rtol=0, atol=1e-10 * scale_of_field)


def test_displacement_fields_of_known_motions(cube_model, cube):
    translation = np.tile([1e-4, -2e-4, 3e-4], (cube.n_nodes, 1))
    fields = cube_model.element_fields(translation)
    assert fields["volume_change"] == pytest.approx(0.0, abs=1e-12)
    np.testing.assert_allclose(fields["von_mises"], 0.0, atol=1e-9)
    np.testing.assert_allclose(fields["max_stretch"], 1.0, rtol=1e-12)
    dilation = 0.01 * (cube.points - cube.points.mean(axis=0))
    fields = cube_model.element_fields(dilation)
    assert fields["volume_change"] == pytest.approx(1.01**3 - 1, rel=1e-10)
    np.testing.assert_allclose(fields["max_stretch"], 1.01, rtol=1e-12)


# -- cache ------------------------------------------------------------------------------------
def test_precompute_cache_round_trip_and_corruption(tmp_path, small_box):
    def model(penalty=None):
        return TissueModel(small_box, Material(20e3, 0.45), small_box.node_sets["z0"], penalty)

    first = model().precompute(cache_dir=tmp_path)
    assert not first.from_cache
    second = model().precompute(cache_dir=tmp_path)
    assert second.from_cache
    np.testing.assert_array_equal(second.matrix, first.matrix)
    (data,) = tmp_path.glob("*.npy")
    raw = bytearray(data.read_bytes())
    raw[-8] ^= 0xFF  # flip bits in the last stored value
    data.write_bytes(bytes(raw))
    third = model().precompute(cache_dir=tmp_path)
    assert not third.from_cache
    np.testing.assert_array_equal(third.matrix, first.matrix)
    data.write_bytes(data.read_bytes()[:100])  # truncated
    assert not model().precompute(cache_dir=tmp_path).from_cache
    other = model(penalty=1e6).precompute(cache_dir=tmp_path)
    assert not other.from_cache
    assert len(list(tmp_path.glob("*.npy"))) == 2


def test_on_demand_cache_is_memory_bounded(cube):
    model = TissueModel(cube, Material(20e3, 0.45), cube.node_sets["z0"])
    column_bytes = 3 * (cube.n_nodes + len(model.contact_nodes)) * 3 * 8  # full, and at the candidates
    model = TissueModel(cube, Material(20e3, 0.45), cube.node_sets["z0"], column_cache_bytes=4 * column_bytes)
    for node in cube.node_sets["z1"][:10]:
        model.solve({int(node): (0, 0, -1e-4)})
    assert model.cached_columns == 4 and len(model.evicted_columns) == 6


# -- errors -----------------------------------------------------------------------------------
def test_model_errors_name_the_input(cube, cube_model):
    with pytest.raises(ModelError, match="no fixed nodes"):
        TissueModel(cube, Material(20e3), [])
    with pytest.raises(ModelError, match=r"fixed_nodes contains id 9999 outside 0..728"):
        TissueModel(cube, Material(20e3), [9999])
    with pytest.raises(ModelError, match="must be finite"):
        cube_model.solve({int(cube.node_sets["z1"][0]): (0, np.nan, 0)})
    with pytest.raises(ModelError, match="method must be"):
        cube_model.solve({int(cube.node_sets["z1"][0]): (0, 0, 0)}, method="guess")
    with pytest.raises(ModelError, match="contacts is empty"):
        cube_model.solve({})


@pytest.mark.parametrize(
    ("fixed_nodes", "fixed_dofs", "free"),
    [([], [0], 5), ([0], [], 3), ([0, 1], [], 1), ([], [2, 29, 245], 3)],
)
def test_fixing_too_little_is_rejected(cube, fixed_nodes, fixed_dofs, free):
    """One dof, one node, two nodes (an axis) or only z dofs on a plane leave rigid modes free."""
    with pytest.raises(ModelError, match=f"leave {free} rigid-body mode"):
        TissueModel(cube, Material(20e3), fixed_nodes, fixed_dofs=fixed_dofs)


def test_indefinite_matrix_reported_as_solver_error():
    from sim.errors import SolverError
    from sim.fem.inverse.condensation import sparse_cholesky

    with pytest.raises(SolverError, match="not positive definite"):
        sparse_cholesky(sp.csc_matrix(np.array([[1.0, 2.0], [2.0, 1.0]])))
