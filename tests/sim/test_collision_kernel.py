"""The segment-triangle kernel against an independent exact rational computation."""

from fractions import Fraction

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sim.collision import CollisionInputError, intersect_segments_triangles


def exact_hit(p, q, a, b, c):
    """Plane equation, crossing point and barycentrics solved in exact rationals.

    Returns None for no hit, else (t, (wa, wb, wc), entering). Independent of the
    kernel's orientation-predicate formulation.
    """
    p, q, a, b, c = ([Fraction(float(x)) for x in v] for v in (p, q, a, b, c))

    def sub(x, y):
        return [x[i] - y[i] for i in range(3)]

    def dot(x, y):
        return sum(x[i] * y[i] for i in range(3))

    def cross(x, y):
        return [x[1] * y[2] - x[2] * y[1], x[2] * y[0] - x[0] * y[2], x[0] * y[1] - x[1] * y[0]]

    n = cross(sub(b, a), sub(c, a))
    if dot(n, n) == 0:
        return None  # zero-area triangle: no plane
    dp, dq = dot(n, sub(p, a)), dot(n, sub(q, a))
    if (dp == 0 and dq == 0) or (dp > 0 and dq > 0) or (dp < 0 and dq < 0):
        return None
    t = dp / (dp - dq)
    x = [p[i] + t * (q[i] - p[i]) for i in range(3)]
    nn = dot(n, n)
    wb = dot(cross(sub(x, a), sub(c, a)), n) / nn
    wc = dot(cross(sub(b, a), sub(x, a)), n) / nn
    wa = 1 - wb - wc
    if wa < 0 or wb < 0 or wc < 0:
        return None
    return t, (wa, wb, wc), dp > 0 or (dp == 0 and dq < 0)


def check_against_exact(p, q, tri):
    hits = intersect_segments_triangles(p[None], q[None], tri[None])
    expected = exact_hit(p, q, *tri)
    if expected is None:
        assert len(hits) == 0, (p, q, tri, hits)
        return
    assert len(hits) == 1, (p, q, tri)
    t, weights, entering = expected
    assert hits.t[0] == pytest.approx(float(t), abs=1e-8)
    np.testing.assert_allclose(hits.barycentric[0], [float(w) for w in weights], atol=1e-8)
    assert bool(hits.entering[0]) == entering


# Small integer grids make degenerate configurations (coplanar, through an
# edge or vertex, zero length, zero area) common; scaled reals cover the rest.
grid = st.integers(-3, 3)
grid_point = st.tuples(grid, grid, grid).map(lambda v: np.array(v, dtype=float))
real = st.floats(-1.0, 1.0, allow_nan=False, width=64)
real_point = st.tuples(real, real, real).map(np.array)


@given(grid_point, grid_point, grid_point, grid_point, grid_point)
@settings(max_examples=3000, deadline=None)
def test_agrees_with_exact_arithmetic_on_grid_inputs(p, q, a, b, c):
    check_against_exact(p, q, np.array([a, b, c]))


@given(real_point, real_point, real_point, real_point, real_point)
@settings(max_examples=1500, deadline=None)
def test_agrees_with_exact_arithmetic_on_real_inputs(p, q, a, b, c):
    check_against_exact(p, q, np.array([a, b, c]))


@given(real_point, real_point, real_point, st.floats(0, 1), st.floats(0, 1), st.floats(-1e-12, 1e-12))
@settings(max_examples=1500, deadline=None)
def test_agrees_near_the_plane(a, b, c, s, r, offset):
    """Segments ending on or a hair off the triangle's plane: the hard cases for floats."""
    tri = np.array([a, b, c])
    inside = a + s * (b - a) + r * (1 - s) * (c - a)
    normal = np.cross(b - a, c - a)
    p = inside + offset * normal
    q = inside + normal + 0.1 * (b - a)
    check_against_exact(p, q, tri)


def test_degenerate_cases_by_hand():
    tri = np.array([[[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]])
    up, down = np.array([[0.25, 0.25, 1.0]]), np.array([[0.25, 0.25, -1.0]])
    assert len(intersect_segments_triangles(up, down, tri)) == 1
    assert intersect_segments_triangles(up, down, tri).entering[0]  # normal is +z: coming from the front
    assert not intersect_segments_triangles(down, up, tri).entering[0]
    in_plane = (np.array([[-1.0, 0.2, 0]]), np.array([[2.0, 0.2, 0]]))
    assert len(intersect_segments_triangles(*in_plane, tri)) == 0
    through_edge = intersect_segments_triangles(np.array([[0.5, 0, 1.0]]), np.array([[0.5, 0, -1.0]]), tri)
    np.testing.assert_allclose(through_edge.barycentric[0], [0.5, 0.5, 0.0])
    through_vertex = intersect_segments_triangles(np.array([[0.0, 1, 1.0]]), np.array([[0, 1, -1.0]]), tri)
    np.testing.assert_allclose(through_vertex.barycentric[0], [0, 0, 1.0])
    zero_length = np.array([[0.25, 0.25, 0.0]])
    assert len(intersect_segments_triangles(zero_length, zero_length, tri)) == 0
    flat = np.array([[[0.0, 0, 0], [1, 0, 0], [2, 0, 0]]])
    assert len(intersect_segments_triangles(up, down, flat)) == 0
    touching = intersect_segments_triangles(np.array([[0.25, 0.25, 0.0]]), up, tri)
    assert len(touching) == 1 and touching.t[0] == 0.0
    near_parallel = intersect_segments_triangles(
        np.array([[-1, 0.2, 1e-300]]), np.array([[2, 0.2, -1e-300]]), tri
    )
    assert len(near_parallel) == 1


def test_barycentric_weights_reproduce_the_hit_point():
    rng = np.random.default_rng(1)
    triangles = rng.normal(size=(500, 3, 3))
    starts = rng.normal(size=(40, 3)) * 2
    ends = rng.normal(size=(40, 3)) * 2
    hits = intersect_segments_triangles(starts, ends, triangles)
    assert len(hits) > 0
    on_triangle = np.einsum("ki,kij->kj", hits.barycentric, triangles[hits.triangle])
    np.testing.assert_allclose(on_triangle, hits.points(starts, ends), atol=1e-9)
    np.testing.assert_allclose(hits.barycentric.sum(axis=1), 1.0, rtol=1e-12)
    brute = sum(
        len(intersect_segments_triangles(starts[s : s + 1], ends[s : s + 1], triangles)) for s in range(40)
    )
    assert brute == len(hits)


def test_shared_edge_reports_both_triangles():
    square = np.array([[[0.0, 0, 0], [1, 0, 0], [1, 1, 0]], [[0.0, 0, 0], [1, 1, 0], [0, 1, 0]]])
    hits = intersect_segments_triangles(np.array([[0.5, 0.5, 1.0]]), np.array([[0.5, 0.5, -1.0]]), square)
    assert sorted(hits.triangle.tolist()) == [0, 1]


def test_bad_input_is_named():
    with pytest.raises(CollisionInputError, match=r"triangles must have shape \(n, 3, 3\)"):
        intersect_segments_triangles(np.zeros((1, 3)), np.ones((1, 3)), np.zeros((2, 3)))
    with pytest.raises(CollisionInputError, match="seg_start must have finite coordinates"):
        intersect_segments_triangles(np.full((1, 3), np.nan), np.ones((1, 3)), np.zeros((1, 3, 3)))


def rational_orient3d(a, b, c, d):
    """det[a - d, b - d, c - d] in rationals, written out independently of the kernel."""
    a, b, c, d = ([Fraction(float(x)) for x in v] for v in (a, b, c, d))
    m = [[a[i] - d[i] for i in range(3)], [b[i] - d[i] for i in range(3)], [c[i] - d[i] for i in range(3)]]
    return (
        m[0][0] * m[1][1] * m[2][2]
        + m[0][1] * m[1][2] * m[2][0]
        + m[0][2] * m[1][0] * m[2][1]
        - m[0][2] * m[1][1] * m[2][0]
        - m[0][0] * m[1][2] * m[2][1]
        - m[0][1] * m[1][0] * m[2][2]
    )


# every exponent a double can have, subnormals included, so the common scale is tested at its extremes
any_magnitude = st.floats(allow_nan=False, allow_infinity=False, min_value=-1e100, max_value=1e100)
wide_point = st.tuples(any_magnitude, any_magnitude, any_magnitude).map(np.array)


@given(st.one_of(grid_point, wide_point), wide_point, st.one_of(grid_point, real_point), wide_point)
@settings(max_examples=1500, deadline=None)
def test_integer_orient3d_is_the_exact_determinant(a, b, c, d):
    from sim.collision.predicates import orient3d, orient3d_integer

    expected = rational_orient3d(a, b, c, d)
    numerator, denominator = orient3d_integer(a, b, c, d)
    assert denominator > 0
    assert Fraction(numerator, denominator) == expected
    _, sign = orient3d(a[None], b[None], c[None], d[None], relative_accuracy=1.0)
    assert int(sign[0]) == (expected > 0) - (expected < 0)
