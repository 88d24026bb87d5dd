"""Ray prefiltering by bounding spheres: never loses the nearest hit."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sim.geometry import bounding_spheres, ray_may_hit, ray_triangle_distances

coordinate = st.floats(-1.0, 1.0, allow_nan=False, width=64)
point = st.tuples(coordinate, coordinate, coordinate)


@settings(max_examples=200, deadline=None)
@given(
    origin=point,
    direction=point.filter(lambda d: np.linalg.norm(d) > 1e-3),
    seed=st.integers(0, 2**32 - 1),
    reach=st.floats(0.01, 3.0),
)
def test_prefilter_keeps_every_triangle_the_ray_meets(origin, direction, seed, reach):
    rng = np.random.default_rng(seed)
    centres = rng.uniform(-1, 1, size=(60, 1, 3))
    triangles = centres + rng.uniform(-0.3, 0.3, size=(60, 3, 3))
    origin = np.array(origin)
    unit = np.array(direction) / np.linalg.norm(direction)
    spheres = bounding_spheres(triangles)
    kept = ray_may_hit(origin, unit, *spheres, reach=reach)
    everything = ray_triangle_distances(origin, unit, triangles)
    met = np.flatnonzero(everything <= reach)
    assert set(met.tolist()) <= set(kept.tolist())
    nearest = everything.min()
    prefiltered = ray_triangle_distances(origin, unit, triangles[kept]).min() if kept.size else np.inf
    if nearest <= reach:
        assert prefiltered == nearest


def test_bounding_spheres_hold_their_corners():
    triangles = np.array([[[0.0, 0, 0], [2, 0, 0], [0, 2, 0]]])
    centres, radii = bounding_spheres(triangles)
    np.testing.assert_allclose(centres, [[2 / 3, 2 / 3, 0]])
    assert radii[0] == np.linalg.norm(triangles[0] - centres[0], axis=1).max()


def slab_and_its_inner_top_nodes():
    """A 3 mm slab held at its base, its tissue model, and its top-face nodes off the edges."""
    from sim.fem import Material, TissueModel
    from sim.mesh import box_mesh

    mesh = box_mesh((0.004, 0.004, 0.003), (4, 4, 3))
    model = TissueModel(mesh, Material(20e3, 0.45), mesh.node_sets["z0"])
    top = mesh.node_sets["z1"]
    inner = [int(n) for n in top if 0 < mesh.points[n, 0] < 0.004 and 0 < mesh.points[n, 1] < 0.004]
    return mesh, model, inner


def test_tissue_depth_matches_a_cast_against_every_triangle():
    """The slab is 3 mm thick: every top-face node has exactly that depth below it."""
    _, model, inner = slab_and_its_inner_top_nodes()
    for node in inner:
        assert abs(model.tissue_depth(node) - 0.003) < 1e-12


def test_cast_depths_caches_surface_nodes_and_leaves_the_rest_to_raise_at_contact():
    from sim.errors import ModelError

    mesh, model, top = slab_and_its_inner_top_nodes()
    interior = int(np.flatnonzero(np.all((mesh.points > 1e-6) & (mesh.points < 0.003 - 1e-6), axis=1))[0])
    model.cast_depths([*top, interior])
    assert all(model.knows_depth(n) for n in top) and not model.knows_depth(interior)
    assert all(abs(model.tissue_depth(n) - 0.003) < 1e-12 for n in top)
    with pytest.raises(ModelError, match=f"node {interior} is not on the exterior surface"):
        model.tissue_depth(interior)
