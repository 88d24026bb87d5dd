"""The local-stress operator a contact start builds (sim.fem.fields.LocalStress), and its compiled
steps (sim.fem._local_stress), against a full-field solve and an independent NumPy reference."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse.linalg as sla
from hypothesis import given, settings
from hypothesis import strategies as st

from sim.errors import ModelError
from sim.fem import Material, TissueModel
from sim.fem import _local_stress as compiled
from sim.fem.fields import LocalStress, _reading_bounds
from sim.fem.stress import von_mises_rows


def reference_response(columns, loads, nodes):
    """NumPy: rows of each load node's columns at the nodes' dofs, side by side, times the loads."""
    dofs = (3 * np.asarray(nodes)[:, None] + np.arange(3)).ravel()
    return np.hstack([c[dofs] for c in columns]) @ loads


def reference_rows(response, tets, gradients, lam, mu):
    """NumPy, written as the stress is taught: sigma = lambda tr(eps) I + 2 mu eps, its deviator s,
    and the six components whose norm is sqrt(3/2 s:s)."""
    q = response.shape[1]
    u = response.reshape(-1, 3, q)[tets]  # (E, 4, 3, q)
    grad = np.einsum("maiq,maj->mijq", u, gradients)
    eps = 0.5 * (grad + np.swapaxes(grad, 1, 2))
    trace = np.einsum("miiq->mq", eps)
    eye = np.eye(3)[None, :, :, None]
    sigma = 2 * mu[:, None, None, None] * eps + lam[:, None, None, None] * trace[:, None, None, :] * eye
    s = sigma - np.einsum("miiq->mq", sigma)[:, None, None, :] / 3 * eye
    shear = [np.sqrt(2) * s[:, i, j] for i, j in ((0, 1), (0, 2), (1, 2))]
    parts = [s[:, 0, 0], s[:, 1, 1], s[:, 2, 2], *shear]
    return np.sqrt(1.5) * np.stack(parts, axis=1).reshape(-1, q)


@settings(max_examples=60, deadline=None)
@given(
    k=st.integers(1, 5),
    n=st.integers(5, 30),
    q=st.integers(1, 9),
    local=st.integers(1, 12),
    elements=st.integers(1, 8),
    seed=st.integers(0, 2**32 - 1),
)
def test_the_compiled_steps_equal_the_numpy_reference(k, n, q, local, elements, seed):
    rng = np.random.default_rng(seed)
    columns = [rng.normal(size=(3 * n, 3)) for _ in range(k)]
    loads = rng.normal(size=(3 * k, q))
    loads[: 3 * (k // 2)] *= rng.integers(0, 2)  # sometimes a load node carries nothing
    nodes = rng.integers(0, n, size=local)
    got = np.empty((3 * local, q))
    compiled.response(columns, loads, nodes, got)
    expected = reference_response(columns, loads, nodes)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12 * max(1.0, abs(expected).max()))

    tets = rng.integers(0, local, size=(elements, 4))
    gradients = rng.normal(size=(elements, 4, 3)) * 1e3
    mu = rng.uniform(1e3, 1e6, size=elements)
    lam = mu * rng.uniform(1.0, 50.0, size=elements)  # up to nearly incompressible: lambda cancels
    rows = von_mises_rows(gradients, mu, tets, got)
    reference = reference_rows(got, tets, gradients, lam, mu)
    np.testing.assert_allclose(rows, reference, rtol=0, atol=1e-9 * max(1.0, abs(reference).max()))


def reference_measures(operator, split, deformation, rest, rest_length, forces, scale):
    """NumPy, as LocalStress read its field before the compiled pass: two products and maxima."""
    squares = ((operator @ forces).reshape(-1, 6) ** 2).sum(axis=1)
    local = float(np.sqrt(squares[:split].max())) if split else 0.0
    watched = float(np.sqrt(squares[split:].max())) if len(squares) > split else np.nan
    if not len(rest_length):
        return local, watched, 1.0
    deformed = rest + scale * (deformation @ forces).reshape(-1, 3)
    return local, watched, float(np.sqrt(((deformed**2).sum(axis=1) / rest_length).max()))


@settings(max_examples=150, deadline=None)
@given(
    q=st.integers(1, 9),
    elements=st.integers(0, 40),
    edges=st.integers(0, 30),
    seed=st.integers(0, 2**32 - 1),
    scale=st.floats(-10.0, 10.0),
    decay=st.floats(0.0, 1.0),
    poison=st.sampled_from(["none", "operator", "deformation", "rest", "forces", "zero forces", "huge"]),
)
def test_the_compiled_field_measures_equal_the_numpy_reference(
    q, elements, edges, seed, scale, decay, poison
):
    """The compiled pass equals the NumPy reference (a nan is the answer of its group, as NumPy's max
    says); with each element's and edge's bound it reads only what can hold the largest and answers as
    the whole pass does, bit for bit: the stress falling off away from the load (``decay`` per
    element, the rows shuffled), nan anywhere, no load, loads near overflow."""
    rng = np.random.default_rng(seed)
    split = int(rng.integers(0, elements + 1))
    falloff = np.exp(-decay * rng.permutation(max(elements, 1))[:elements] * 0.5)
    operator = rng.normal(size=(elements, 6, q)) * falloff[:, None, None] * 1e4
    operator = operator.reshape(6 * elements, q)
    deformation = rng.normal(size=(edges, 3, q)) * np.exp(-decay * np.arange(edges))[:, None, None] * 1e-4
    deformation = deformation.reshape(3 * edges, q)
    rest = rng.normal(size=(edges, 3)) * 1e-3
    rest_length = (rest**2).sum(axis=1)
    forces = rng.normal(size=q)
    where = int(rng.integers(0, 1 << 30))
    if poison == "operator" and elements:
        operator[where % (6 * elements), where % q] = np.nan
    if poison == "deformation" and edges:
        deformation[where % (3 * edges), where % q] = np.nan
    if poison == "rest" and edges:
        rest[where % edges, 0] = np.nan
    if poison == "forces":
        forces[where % q] = np.nan
    if poison == "zero forces":
        forces[:] = 0.0
    if poison == "huge":
        forces *= 1e150
    args = (operator, split, deformation, rest, rest_length, forces, scale)
    whole = compiled.measures(*args)
    if poison != "huge":  # near overflow the two sum in different orders: inf or not
        np.testing.assert_allclose(whole, reference_measures(*args), rtol=1e-12, atol=0)
    bounded = compiled.measures(*args, *_reading_bounds(operator, split, deformation, rest, rest_length))
    np.testing.assert_array_equal(bounded, whole)


def test_the_bounds_are_the_norms_they_say():
    """Each element's squared Frobenius norm and column norms, each edge's first- and second-order gains
    and the largest rest ratio, against NumPy's."""
    rng = np.random.default_rng(7)
    q, elements, edges, split = 6, 40, 25, 17
    operator = (
        rng.normal(size=(6 * elements, q)) * np.repeat(np.exp(-rng.uniform(0, 5, elements)), 6)[:, None]
    )
    deformation, rest = rng.normal(size=(3 * edges, q)), rng.normal(size=(edges, 3))
    rest_length = (rest**2).sum(axis=1) * rng.uniform(0.9, 1.1, edges)
    order, element_bound, edge_order, edge_bound, base = _reading_bounds(
        operator, split, deformation, rest, rest_length
    )
    blocks = operator.reshape(-1, 6, q)
    np.testing.assert_allclose(element_bound[:, 0], (blocks**2).sum(axis=(1, 2))[order], rtol=1e-14)
    np.testing.assert_allclose(element_bound[:, 1:], np.sqrt((blocks**2).sum(axis=1))[order], rtol=1e-14)
    assert sorted(order[:split]) == list(range(split)) and sorted(order[split:]) == list(
        range(split, elements)
    )
    assert (np.diff(element_bound[:split, 0]) <= 0).all() and (np.diff(element_bound[split:, 0]) <= 0).all()
    rows = deformation.reshape(-1, 3, q)
    along = np.linalg.norm(np.einsum("eiq,ei->eq", rows, rest), axis=1) / rest_length
    spread = (rows**2).sum(axis=(1, 2)) / rest_length
    np.testing.assert_allclose(edge_bound[:, 0], along[edge_order], rtol=1e-14)
    np.testing.assert_allclose(edge_bound[:, 2], spread[edge_order], rtol=1e-14)
    np.testing.assert_allclose(
        edge_bound[:, 1], [spread[edge_order][k:].max() for k in range(edges)], rtol=1e-14
    )
    assert base == pytest.approx(((rest**2).sum(axis=1) / rest_length).max(), rel=1e-14)
    with pytest.raises(ValueError, match=r"operator \(6E, 6\) and elements \(E, 7\) do not fit"):
        compiled.measure_bounds(
            operator, q, deformation, rest, rest_length, np.empty((elements, 6)), np.empty((25, 2))
        )
    with pytest.raises(ValueError, match="must match rest_length's 24 edges"):
        compiled.measure_bounds(
            operator,
            q,
            deformation,
            rest,
            rest_length[:24].copy(),
            np.empty((elements, 7)),
            np.empty((24, 2)),
        )


def test_bounded_measures_refuse_orders_that_do_not_fit():
    operator, deformation, rest = np.ones((12, 3)), np.ones((6, 3)), np.eye(3)[:2].copy()
    args = (operator, 1, deformation, rest, np.ones(2), np.ones(3), 1.0)
    order, bound, edge_order, edge_bound, base = _reading_bounds(*args[:5])
    with pytest.raises(IndexError, match=r"element order entry 0 \(1\) is outside its group \[0, 1\)"):
        compiled.measures(*args, order[::-1].copy(), bound, edge_order, edge_bound, base)
    with pytest.raises(IndexError, match=r"edge order entry 1 \(2\)"):
        compiled.measures(*args, order, bound, np.array([0, 2]), edge_bound, base)
    with pytest.raises(ValueError, match="element order and bounds must hold 2 and 8 entries; got 2 and 4"):
        compiled.measures(*args, order, bound[:1].copy(), edge_order, edge_bound, base)
    with pytest.raises(TypeError, match="takes the element order and bounds with the edge order and bounds"):
        compiled.measures(*args, order)


def test_compiled_field_measures_refuse_what_does_not_fit():
    rest = np.eye(3)[:2].copy()  # two unit edges, unloaded: stretch 1
    args = (np.zeros((12, 3)), 1, np.zeros((6, 3)), rest, np.ones(2), np.zeros(3), 1.0)
    assert compiled.measures(*args) == (0.0, 0.0, 1.0)
    with pytest.raises(ValueError, match=r"operator must be \(6E, 5\)"):
        compiled.measures(args[0], 1, args[2], args[3], args[4], np.zeros(5), 1.0)
    with pytest.raises(ValueError, match="split must be within the operator's 2 elements"):
        compiled.measures(args[0], 3, *args[2:])
    with pytest.raises(ValueError, match="must match rest_length's 3 edges"):
        compiled.measures(args[0], 1, args[2], args[3], np.ones(3), *args[5:])
    with pytest.raises(TypeError, match="forces must be float64"):
        compiled.measures(*args[:5], np.zeros(3, dtype=np.float32), 1.0)


def test_compiled_steps_refuse_what_does_not_fit():
    columns = [np.zeros((30, 3)), np.zeros((30, 3))]
    out = np.empty((6, 2))
    with pytest.raises(ValueError, match="loads must hold 3 rows per load node"):
        compiled.response(columns, np.zeros((5, 2)), np.array([0, 1]), out)
    with pytest.raises(ValueError, match="out must hold 12 values"):
        compiled.response(columns, np.zeros((6, 2)), np.array([0, 1]), np.empty((5, 2)))
    with pytest.raises(IndexError, match="local node 10 is not a node of a 10-node mesh"):
        compiled.response(columns, np.zeros((6, 2)), np.array([0, 10]), out)
    with pytest.raises(ValueError, match=r"column block 1 must be \(3N, 3\)"):
        compiled.response([np.zeros((30, 3)), np.zeros((27, 3))], np.zeros((6, 2)), np.array([0, 1]), out)
    with pytest.raises(TypeError, match="loads must be float64"):
        compiled.response(columns, np.zeros((6, 2), dtype=np.float32), np.array([0, 1]), out)
    with pytest.raises(TypeError, match="nodes must be int64"):
        compiled.response(columns, np.zeros((6, 2)), np.array([0, 1], dtype=np.int32), out)
    with pytest.raises(TypeError, match="out must be a C-contiguous writable array"):
        compiled.response(columns, np.zeros((6, 2)), np.array([0, 1]), np.empty((2, 6)).T)
    with pytest.raises(IndexError, match="tets name local node 2 of 2"):
        von_mises_rows(np.zeros((1, 4, 3)), np.ones(1), np.array([[0, 1, 1, 2]]), np.zeros((6, 2)))
    with pytest.raises(ValueError, match="must match mu's 2 elements"):
        compiled.von_mises_rows(np.zeros((6, 2)), np.zeros((1, 4), np.int64), np.zeros(12), np.ones(2), out)


@pytest.fixture(scope="module")
def wall(small_box):
    """A nearly incompressible block (nu = 0.47, the stable limit) clamped at its base: lambda is 15.7 mu."""
    return TissueModel(small_box, Material(20e3, 0.47), small_box.node_sets["z0"])


def full_field_von_mises(model: TissueModel, nodes, nodal_forces) -> np.ndarray:
    """Every element's von Mises stress (Pa) for forces (N) on nodes: one SuperLU solve of the
    penalised stiffness, then sigma = lambda tr(eps) I + 2 mu eps per element."""
    rhs = np.zeros(3 * model.mesh.n_nodes)
    rhs[(3 * np.asarray(nodes)[:, None] + np.arange(3)).ravel()] = nodal_forces.ravel()
    u = sla.spsolve(model.penalised_stiffness().tocsc(), rhs).reshape(-1, 3)
    grad = np.einsum("mai,maj->mij", u[model.mesh.tets], model.element_gradients)
    eps = 0.5 * (grad + np.swapaxes(grad, 1, 2))
    lam, mu = model.lame
    trace = np.trace(eps, axis1=1, axis2=2)
    sigma = 2 * mu[:, None, None] * eps + (lam * trace)[:, None, None] * np.eye(3)
    s = sigma - np.trace(sigma, axis1=1, axis2=2)[:, None, None] / 3 * np.eye(3)
    return np.sqrt(1.5 * np.einsum("mij,mij->m", s, s))


@pytest.mark.parametrize("cached", [False, True])
def test_local_stress_is_the_full_fields_largest_von_mises_near_the_contact(wall, small_box, cached):
    """A kernel-like load (three nodes' weights times one 3-D force) and plain nodal forces: the
    operator's maximum equals the largest von Mises stress of the same elements in a full solve,
    whether it reads cached whole columns (the compiled gather) or solves its q columns."""
    top = small_box.node_sets["z1"]
    centre = small_box.points[top].mean(axis=0)
    nodes = top[np.argsort(np.linalg.norm(small_box.points[top] - centre, axis=1))[:3]]
    wall.drop_cached_columns()
    if cached:
        wall.prefetch(nodes, full=True)
    weights = np.array([0.5, 0.3, 0.2])
    rng = np.random.default_rng(11)
    for force_map in (np.kron(weights[:, None], np.eye(3)), np.eye(9)):
        operator = LocalStress(wall, nodes, force_map, [centre])
        assert operator.elements.size
        for _ in range(3):
            forces = rng.normal(size=force_map.shape[1]) * 0.2
            expected = full_field_von_mises(wall, nodes, (force_map @ forces).reshape(-1, 3))
            assert operator.maximum(forces) == pytest.approx(expected[operator.elements].max(), rel=1e-9)
    assert wall.spot_solved == []  # prefetched or solved as q columns: no whole column solved on the spot


def test_a_load_on_a_node_outside_the_mesh_is_refused(wall):
    with pytest.raises(ModelError, match="nodes contains id"):
        wall.load_response([wall.mesh.n_nodes], np.eye(3), [0])
