"""The continuous collision test compiled: its crossings (sim/collision/_crossings.c) against the NumPy path
they replace (candidate_pairs then intersect_pairs): the same hits, bit for bit and in the same order,
the pairs floating point is not sure of decided exactly; and its broad phase's grid
(sim/collision/_grid.c) against the KD-tree queries it replaced."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sim.collision import _crossings
from sim.collision.mesh import CollisionMesh
from sim.collision.segments import (
    SegmentHits,
    bounding_boxes,
    candidate_pairs,
    compiled_crossings,
    intersect_pairs,
    plane_crossing,
)
from sim.mesh import box_mesh


def numpy_path(start, end, corners, triangles) -> SegmentHits:
    lower, upper = bounding_boxes(corners[triangles])
    segments, local = candidate_pairs(start, end, lower, upper)
    return intersect_pairs(start, end, corners, segments, triangles[local])


def assert_same(compiled: SegmentHits, reference: SegmentHits) -> None:
    for name in ("segment", "triangle", "t", "barycentric", "entering"):
        ours, theirs = getattr(compiled, name), getattr(reference, name)
        assert ours.dtype == theirs.dtype and ours.shape == theirs.shape, name
        np.testing.assert_array_equal(ours, theirs, err_msg=name)  # equal values, not only close ones


grid = st.integers(-2, 2).map(float)
coordinate = st.one_of(grid, st.floats(-2.0, 2.0, allow_nan=False, width=64))
points = st.integers(1, 6).flatmap(
    lambda n: st.lists(st.tuples(coordinate, coordinate, coordinate), min_size=n, max_size=n)
)


@given(
    st.lists(st.tuples(coordinate, coordinate, coordinate), min_size=3, max_size=24),
    points,
    st.randoms(use_true_random=False),
)
@settings(max_examples=800, deadline=None)
def test_the_same_hits_as_the_numpy_path_whatever_the_input(corner_list, ends, random):
    """Grid coordinates make segments through edges and vertices and in planes (the pairs floating
    point is not sure of, decided exactly) common; reals cover the rest."""
    corners = np.array(corner_list[: len(corner_list) // 3 * 3], dtype=float).reshape(-1, 3, 3)
    start = np.array(ends, dtype=float)
    end = start[::-1].copy() + np.array([random.uniform(-1, 1) for _ in range(3)])
    triangles = np.array(
        random.sample(range(len(corners)), random.randint(1, len(corners))), dtype=np.int64
    )  # any subset, in any order: the order of the listed ids is the hits' order
    assert_same(
        compiled_crossings(start, end, corners, triangles), numpy_path(start, end, corners, triangles)
    )


def test_a_needle_through_a_box_mesh_finds_what_numpy_finds():
    """Real inputs (a needle polyline swept through the cube's top), every triangle listed: all the
    hits."""
    mesh = box_mesh(0.01, 6)
    collision = CollisionMesh(mesh)
    rng = np.random.default_rng(7)
    triangles = np.arange(len(collision.corners), dtype=np.int64)
    hits = 0
    for _ in range(200):
        start = rng.uniform(-0.002, 0.012, size=(9, 3))
        end = start + rng.normal(0, 0.004, size=(9, 3))
        found = compiled_crossings(start, end, collision.corners, triangles)
        assert_same(found, numpy_path(start, end, collision.corners, triangles))
        hits += len(found)
        assert_same(collision.crossings_among(start, end, triangles), found)
    assert hits > 100


def test_unsure_pairs_are_decided_exactly_in_their_place():
    """A segment lying in a triangle's plane (both ends' determinants exactly zero) is not decided in
    floating point: the compiled test hands that pair to the exact path (no hit) and keeps the hits
    before and after it in the NumPy path's order."""
    corners = np.array(
        [
            [[0, 0, 0], [1, 0, 0], [0, 1, 0]],
            [[0, 0, 1], [1, 0, 1], [0, 1, 1]],
            [[0, 0, -1], [1, 0, -1], [0, 1, -1]],
        ],
        dtype=float,
    )
    triangles = np.array([1, 0, 2], dtype=np.int64)
    start = np.array([[0.1, 0.1, 0.0], [0.2, 0.2, 2.0]])  # in the plane of triangle 0; down through all three
    end = np.array([[0.3, 0.2, 0.0], [0.2, 0.2, -2.0]])
    columns = _crossings.crossings(start, end, corners, triangles, 1.1e-16, 1e-9)
    assert np.frombuffer(columns[6], dtype=np.int64).tolist() == [0]  # one pair left to the exact path
    found = compiled_crossings(start, end, corners, triangles)
    assert found.segment.tolist() == [1, 1, 1] and found.triangle.tolist() == [1, 0, 2]
    np.testing.assert_allclose(found.t, [0.25, 0.5, 0.75])
    assert found.entering.all()  # from the front (+z)
    np.testing.assert_allclose(found.barycentric, [[0.6, 0.2, 0.2]] * 3)
    assert_same(found, numpy_path(start, end, corners, triangles))


def test_nan_segments_meet_nothing_and_bad_input_is_refused():
    corners = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]], dtype=float)
    start, end = np.array([[0.2, 0.2, 1.0], [np.nan, 0, 0]]), np.array([[0.2, 0.2, -1.0], [0, 0, 0]])
    found = compiled_crossings(start, end, corners, np.array([0], dtype=np.int64))
    assert len(found) == 0  # as NumPy: a NaN spoils every segment's box
    assert len(numpy_path(start, end, corners, np.array([0]))) == 0
    with pytest.raises(ValueError, match="triangle id 3 is not one of the 1 triangles"):
        _crossings.crossings(start, end, corners, np.array([3], dtype=np.int64), 1e-16, 1e-9)
    with pytest.raises(ValueError, match=r"start and end must be \(S, 3\) alike"):
        _crossings.crossings(start, end[:1], corners, np.array([0], dtype=np.int64), 1e-16, 1e-9)
    with pytest.raises(TypeError, match="triangles must be int64"):
        _crossings.crossings(start, end, corners, np.array([0], dtype=np.int32), 1e-16, 1e-9)


@given(st.integers(0, 400), st.integers(1, 12), st.floats(1e-4, 5e-3), st.integers(0, 2**32 - 1))
@settings(max_examples=300, deadline=None)
def test_the_grid_finds_what_a_kd_tree_finds(count, balls, cell, seed):
    """PointGrid.within against scipy's cKDTree.query_ball_point then numpy.unique (the broad phase it
    replaced), with balls inside, across and outside the points' extent, some of them empty."""
    from scipy.spatial import cKDTree

    from sim.collision.grid import PointGrid

    rng = np.random.default_rng(seed)
    points = rng.uniform(-0.01, 0.01, size=(count, 3)) * rng.uniform(0.1, 1.0, size=3)
    centres = rng.uniform(-0.015, 0.015, size=(balls, 3))
    radii = rng.uniform(0.0, 0.006, size=balls)
    radii[rng.random(balls) < 0.2] = 0.0
    found = PointGrid(points, cell).within(centres, radii)
    if count:
        lists = cKDTree(points).query_ball_point(centres, radii, return_sorted=False)
        expected = np.unique(np.concatenate([np.asarray(f, dtype=np.int64) for f in lists]))
    else:
        expected = np.zeros(0, dtype=np.int64)
    assert found.dtype == np.int64
    np.testing.assert_array_equal(found, expected)


def test_the_grid_refuses_what_it_cannot_read():
    from sim.collision import _grid
    from sim.collision.grid import PointGrid

    with pytest.raises(ValueError, match="finite points"):
        PointGrid(np.array([[0.0, 0.0, np.nan]]), 1e-3)
    grid = PointGrid(np.zeros((2, 3)), 1e-3)
    assert len(grid.within(np.zeros((1, 3)), np.array([np.nan]))) == 0  # a NaN ball holds nothing
    with pytest.raises(ValueError, match="one start per cell"):
        _grid.within(np.zeros((1, 3)), np.ones(1), grid._points, grid._ids, grid._starts[:1], grid.origin,
                     grid.cell, grid.dims)  # fmt: skip
    with pytest.raises(ValueError, match="id 5 is not one of the 2 points"):
        _grid.within(np.zeros((1, 3)), np.ones(1), grid._points, np.array([0, 5]), grid._starts,
                     grid.origin, grid.cell, grid.dims)  # fmt: skip


def test_the_global_test_and_the_edge_sweep_find_what_numpy_finds():
    """CollisionMesh.crossings (the graphics layer's global test over its x-sorted window) and
    edges_among (surface edges through a segment's swept path) against the NumPy path they took."""
    collision = CollisionMesh(box_mesh(0.01, 6))
    rng = np.random.default_rng(11)
    found = 0
    for _ in range(100):
        start = rng.uniform(-0.002, 0.012, size=(9, 3))
        end = start + rng.normal(0, 0.004, size=(9, 3))
        keys = collision._sorted_lower[:, 0]
        low_x = min(start[:, 0].min(), end[:, 0].min()) - collision._widest_x
        high_x = max(start[:, 0].max(), end[:, 0].max())
        window = slice(int(np.searchsorted(keys, low_x, "left")), int(np.searchsorted(keys, high_x, "right")))
        pairs, local = candidate_pairs(
            start, end, collision._sorted_lower[window], collision._sorted_upper[window]
        )
        reference = intersect_pairs(
            start, end, collision.corners, pairs, collision._sorted_ids[window][local]
        )
        hits = collision.crossings(start, end)
        assert_same(hits, reference)
        swept = rng.uniform(-0.002, 0.012, size=(4, 3, 3))
        edges = rng.choice(len(collision.edges), size=60, replace=False)
        ends = collision.points[collision.edges[edges]]
        lower, upper = bounding_boxes(swept)
        pairs, given = candidate_pairs(ends[:, 0], ends[:, 1], lower, upper)
        reference_hits = intersect_pairs(ends[:, 0], ends[:, 1], swept, pairs, given)
        crossed, edge_hits = collision.edges_among(swept, edges)
        np.testing.assert_array_equal(crossed, edges[reference_hits.segment])
        assert_same(edge_hits, reference_hits)
        found += len(hits) + len(edge_hits)
    assert found > 50


def test_an_update_of_a_few_nodes_equals_the_whole_recomputation():
    """CollisionMesh.update recomputes only the triangles on nodes that moved: every array it keeps
    equals a full recomputation's, value for value, through grasps, releases back to rest and a
    valid-triangle mask; each update gives new arrays (the corners' identity says they changed)."""
    mesh = box_mesh((0.01, 0.008, 0.003), (10, 8, 3))
    valid = np.ones(len(mesh.surface_triangles), dtype=bool)
    valid[::7] = False
    rng = np.random.default_rng(5)
    for mask in (None, valid):
        moving = CollisionMesh(mesh, mask)
        for step in range(12):
            points = mesh.points.copy()
            if step % 4 != 3:  # a grasp of a few nodes, then back to rest every fourth step
                nodes = rng.choice(mesh.n_nodes, size=rng.integers(1, 30), replace=False)
                points[nodes] += rng.normal(0, 2e-4, size=(len(nodes), 3))
            corners_before = moving.corners
            moving.update(points)
            whole = CollisionMesh(mesh, mask)
            whole._recompute(points.copy(), None)  # every triangle
            for name in ("points", "corners", "normals", "_sorted_ids", "_sorted_lower", "_sorted_upper"):
                np.testing.assert_array_equal(getattr(moving, name), getattr(whole, name), err_msg=name)
            assert moving._widest_x == whole._widest_x and moving._moved == whole._moved
            changed = not np.array_equal(corners_before, moving.corners)
            assert (moving.corners is not corners_before) or not changed


def numpy_plane_crossing(vertices, normal, point):
    """The NumPy the compiled plane crossing replaced (NeedleInteraction._needle_point_at_plane)."""
    side = vertices.dot(normal) - float(point.dot(normal))
    sign = np.sign(side)
    (crossing,) = np.nonzero(sign[:-1] != sign[1:])
    if crossing.size == 0:
        return None
    a, b = side[crossing], side[crossing + 1]
    t = a / (a - b)
    points = vertices[crossing] + t[:, None] * (vertices[crossing + 1] - vertices[crossing])
    offsets = points - point
    return points[np.argmin(np.einsum("ij,ij->i", offsets, offsets))]


@settings(max_examples=300, deadline=None)
@given(
    vertices=st.integers(2, 30),
    seed=st.integers(0, 2**32 - 1),
    kind=st.sampled_from(["curve", "zigzag", "on the plane", "nan", "parallel"]),
)
def test_the_compiled_plane_crossing_is_the_numpy_one(vertices, seed, kind):
    """A needle's polyline against a plane: the same crossing (the nearest, the first of equals, a
    vertex on the plane, a nan) or None, to rounding."""
    rng = np.random.default_rng(seed)
    normal = rng.normal(size=3)
    normal /= np.linalg.norm(normal)
    point = rng.normal(size=3) * 1e-3
    if kind == "curve":  # a needle's arc through the plane, possibly twice
        angles = np.linspace(0.0, rng.uniform(0.5, 3.0), vertices)
        radius = rng.uniform(2e-3, 8e-3)
        line = point + radius * np.column_stack([np.cos(angles), np.sin(angles), np.zeros(vertices)])
        line = line @ np.linalg.qr(rng.normal(size=(3, 3)))[0]
    else:
        line = point + rng.normal(size=(vertices, 3)) * 2e-3
    if kind == "on the plane":  # vertices exactly on it (a zero sign), a crossing at a vertex
        line[:: max(1, vertices // 3)] = point
    if kind == "parallel":  # nowhere across it
        offset = np.abs(rng.normal()) * 1e-3 + 1e-4
        line = line - np.outer(line @ normal - point @ normal, normal) + offset * normal
    if kind == "nan":
        line[int(rng.integers(0, vertices))] = np.nan
    line = np.ascontiguousarray(line)
    got = plane_crossing(line, normal, point)
    expected = numpy_plane_crossing(line, normal, point)
    if expected is None:
        assert got is None
        return
    assert got is not None
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-18)


def test_the_plane_crossing_refuses_what_does_not_fit():
    with pytest.raises(ValueError, match=r"vertices must be \(V, 3\) and normal and point \(3,\); got 4"):
        plane_crossing(np.zeros(4), np.ones(3), np.zeros(3))
    with pytest.raises(TypeError, match="normal must be float64"):
        plane_crossing(np.zeros((2, 3)), np.ones(3, dtype=np.float32), np.zeros(3))
    assert plane_crossing(np.zeros((0, 3)), np.ones(3), np.zeros(3)) is None
