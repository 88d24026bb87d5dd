import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sim.errors import MeshError
from sim.mesh import Calcification, TetMesh, Wound, box_mesh, load_mesh, save_mesh, vessel_mesh


def surface_volume(mesh: TetMesh) -> float:
    """Volume enclosed by the exterior surface (divergence theorem), independent of the tets."""
    p = mesh.points[mesh.surface_triangles]
    return float(np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum() / 6.0)


def test_paper_cube_has_the_papers_sizes(cube):
    assert cube.n_nodes == 729
    assert cube.n_elements == 3072
    assert len(cube.surface_triangles) == 6 * 8 * 8 * 2
    assert np.all(cube.element_volumes > 0)
    assert cube.volume == pytest.approx(1e-6, rel=1e-12)
    np.testing.assert_allclose(cube.element_volumes, 1e-6 / 3072, rtol=1e-9)


def test_surface_is_closed_and_outward(cube):
    assert surface_volume(cube) == pytest.approx(cube.volume, rel=1e-12)
    centroids = cube.points[cube.surface_triangles].mean(axis=1)
    outward = np.einsum("ij,ij->i", centroids - [0.005, 0.005, 0.005], cube.surface_normals)
    assert np.all(outward > 0)
    assert len(cube.surface_nodes) == 729 - 7**3


@given(
    size=st.tuples(*[st.floats(1e-3, 0.1)] * 3),
    divisions=st.tuples(*[st.integers(1, 4)] * 3),
)
@settings(max_examples=25, deadline=None)
def test_box_volume_and_counts(size, divisions):
    mesh = box_mesh(size, divisions)
    assert mesh.n_elements == 6 * math.prod(divisions)
    assert mesh.n_nodes == math.prod(d + 1 for d in divisions)
    assert mesh.volume == pytest.approx(math.prod(size), rel=1e-10)
    assert surface_volume(mesh) == pytest.approx(mesh.volume, rel=1e-10)


@pytest.mark.parametrize("n_theta", [12, 24, 48])
def test_tube_volume_is_the_polygonal_annulus(n_theta):
    r, t, length = 0.004, 0.0015, 0.02
    mesh = vessel_mesh(r, t, length, circumferential_divisions=n_theta, radial_divisions=3, axial_divisions=5)
    exact = 0.5 * n_theta * math.sin(2 * math.pi / n_theta) * ((r + t) ** 2 - r**2) * length
    assert mesh.volume == pytest.approx(exact, rel=1e-12)
    assert surface_volume(mesh) == pytest.approx(exact, rel=1e-10)
    assert sorted(mesh.region_names.values()) == ["adventitia", "intima", "media"]


def test_vessel_patch_with_wound_and_calcification():
    wound = Wound(angle_deg=0.0, z_start=0.005, z_end=0.015, gap=0.0)
    plaque = Calcification(angle_range_deg=(20, 50), z_range=(0.0, 0.02), layers=(1,))
    mesh = vessel_mesh(
        arc_deg=120, circumferential_divisions=24, axial_divisions=20, wound=wound, calcification=plaque
    )
    plain = vessel_mesh(arc_deg=120, circumferential_divisions=24, axial_divisions=20)
    a, b = mesh.node_sets["wound_a"], mesh.node_sets["wound_b"]
    assert len(a) == len(b) == 4 * 9  # 4 node rings through the wall x 9 interior axial rings
    np.testing.assert_array_equal(mesh.points[a], mesh.points[b])  # zero gap: coincident edges
    # Each slit face adds 2 x (radial cells x axial cells) triangles per side.
    assert len(mesh.surface_triangles) == len(plain.surface_triangles) + 2 * 2 * 3 * 10
    assert "calcified" in mesh.region_names.values()
    assert mesh.volume == pytest.approx(plain.volume, rel=1e-12)


def test_wound_gap_opens_the_edges():
    mesh = vessel_mesh(arc_deg=90, circumferential_divisions=18, wound=Wound(0, 0.004, 0.016, gap=3e-4))
    a, b = mesh.node_sets["wound_a"], mesh.node_sets["wound_b"]
    separation = np.linalg.norm(mesh.points[a] - mesh.points[b], axis=1)
    assert separation.max() == pytest.approx(3e-4, rel=0.02)
    assert np.all(mesh.element_volumes > 0)


def test_wound_too_wide_is_rejected():
    with pytest.raises(MeshError, match="wound gap 5 mm is wider than the grid allows"):
        vessel_mesh(arc_deg=90, circumferential_divisions=18, wound=Wound(0, 0.004, 0.016, gap=5e-3))


UNIT_TET = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)


@pytest.mark.parametrize(
    ("points", "tets", "message"),
    [
        (UNIT_TET, [[0, 2, 1, 3]], r"mesh element 0 is inverted .*nodes 0, 2, 1, 3"),
        (
            np.vstack([UNIT_TET, [[0.5, 0.5, 0]]]),
            [[0, 1, 2, 3], [0, 1, 2, 4]],
            r"mesh element 1 has zero volume \(nodes 0, 1, 2, 4\)",
        ),
        (np.vstack([UNIT_TET, [[5, 5, 5]]]), [[0, 1, 2, 3]], r"mesh node 4 is not used by any element"),
        (np.vstack([UNIT_TET[:3], [[0, 0, np.nan]]]), [[0, 1, 2, 3]], r"mesh point 3 is not finite"),
        (UNIT_TET, [[0, 1, 2, 7]], r"mesh element 0 references node 7, but the mesh has 4 nodes"),
        (UNIT_TET[:, :2], [[0, 1, 2, 3]], r"mesh points must have shape \(N, 3\)"),
        (UNIT_TET, [[0, 1, 2]], r"mesh elements must have shape \(M, 4\)"),
    ],
)
def test_bad_meshes_are_rejected_with_the_element_named(points, tets, message):
    with pytest.raises(MeshError, match=message):
        TetMesh(points, tets)


def test_non_manifold_surface_is_rejected():
    # Two tets touching along one edge only: that edge has 4 exterior triangles.
    points = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [0.5, -1, 0], [0.5, 0, -1]], float)
    tets = np.array([[0, 1, 2, 3], [0, 1, 5, 4]])
    with pytest.raises(MeshError, match=r"mesh surface is not manifold: edge \(0, 1\) belongs to 4"):
        TetMesh(points, _positive(points, tets))


def test_face_shared_by_three_elements_is_rejected():
    points = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, -1], [0.3, 0.3, 0.5]], float)
    tets = np.array([[0, 1, 2, 3], [0, 1, 2, 4], [0, 1, 2, 5]])
    with pytest.raises(MeshError, match=r"mesh face \(0, 1, 2\) is shared by 3 elements \(0, 1, 2\)"):
        TetMesh(points, _positive(points, tets))


def _positive(points, tets):
    from sim.mesh.generators import orient_positive

    return orient_positive(points, np.asarray(tets))


@pytest.mark.parametrize("suffix", [".vtu", ".msh"])
def test_mesh_round_trip(tmp_path, suffix):
    mesh = vessel_mesh(
        arc_deg=90,
        circumferential_divisions=6,
        axial_divisions=4,
        calcification=Calcification((-20, 20), (0, 0.02)),
    )
    path = save_mesh(mesh, tmp_path / f"wall{suffix}")
    loaded = load_mesh(path)
    np.testing.assert_allclose(loaded.points, mesh.points)
    np.testing.assert_array_equal(loaded.tets, mesh.tets)
    np.testing.assert_array_equal(loaded.regions, mesh.regions)
    if suffix == ".vtu":
        for name, ids in mesh.node_sets.items():
            np.testing.assert_array_equal(loaded.node_sets[name], ids)


def test_load_mesh_errors(tmp_path):
    with pytest.raises(MeshError, match="does not exist"):
        load_mesh(tmp_path / "missing.vtu")
    import meshio

    triangles = tmp_path / "surface.vtu"
    meshio.write(triangles, meshio.Mesh(UNIT_TET, [("triangle", np.array([[0, 1, 2]]))]))
    with pytest.raises(MeshError, match=r"has no linear tetrahedra \(cell types: triangle\)"):
        load_mesh(triangles)
    inverted = tmp_path / "inverted.vtu"
    meshio.write(inverted, meshio.Mesh(UNIT_TET, [("tetra", np.array([[0, 2, 1, 3]]))]))
    with pytest.raises(MeshError, match=r"inverted.vtu: mesh element 0 is inverted"):
        load_mesh(inverted)
    assert load_mesh(inverted, reorient=True).volume == pytest.approx(1 / 6)
    for k, index in enumerate((-1, 4, 4 + 7, 2**40)):  # issue 23 (7): IndexError, or -1 the last node
        outside = tmp_path / f"outside{k}.vtu"
        meshio.write(outside, meshio.Mesh(UNIT_TET, [("tetra", np.array([[0, 1, 2, index]]))]))
        with pytest.raises(
            MeshError, match=rf"tetrahedron 0 refers to node {index}, but the file has nodes 0..3"
        ):
            load_mesh(outside)
    # issue 23 (7): messages quote the file's node ids, not those left after unused nodes are dropped
    spare = np.vstack([[[9.0, 9.0, 9.0]] * 5, UNIT_TET, [[0.5, 0.5, 0.0]]])  # nodes 0-4 unused
    flat = tmp_path / "flat.vtu"
    meshio.write(flat, meshio.Mesh(spare, [("tetra", np.array([[5, 6, 7, 8], [5, 6, 7, 9]]))]))
    with pytest.raises(MeshError, match=r"flat.vtu: mesh element 1 has zero volume \(nodes 5, 6, 7, 9\)"):
        load_mesh(flat)
    mirrored = tmp_path / "mirrored.vtu"
    meshio.write(mirrored, meshio.Mesh(spare, [("tetra", np.array([[5, 7, 6, 8]]))]))
    with pytest.raises(MeshError, match=r"mesh element 0 is inverted .*nodes 5, 7, 6, 8\)"):
        load_mesh(mirrored)
    garbage = tmp_path / "garbage.vtu"
    garbage.write_bytes(b"\x00not a mesh")
    with pytest.raises(MeshError, match="could not be read"):
        load_mesh(garbage)
