"""Hostile input, round 3 (issue 45, seen 6): a surface with a NaN vertex crashed `vascsim tasks add`
with SIGSEGV inside TetGen; a PLY face naming vertex -1 printed an IndexError traceback. Both are
now one-line errors naming the element, and the mesher never sees them. Run as a separate process:
a crash must fail this test, not end the test run."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

VASCSIM = str(Path(sys.executable).with_name("vascsim"))

SQUARE = [(0, 0, 0), (10, 0, 0), (10, 10, 0), (0, 10, 0), (5, 5, 8)]
FACES = [(0, 1, 4), (1, 2, 4), (2, 3, 4), (3, 0, 4), (0, 2, 1), (0, 3, 2)]


def _stl(path: Path, points, faces) -> Path:
    lines = ["solid t"]
    for face in faces:
        lines += ["facet normal 0 0 0", "outer loop"]
        lines += [f"vertex {points[i][0]} {points[i][1]} {points[i][2]}" for i in face]
        lines += ["endloop", "endfacet"]
    path.write_text("\n".join([*lines, "endsolid t", ""]))
    return path


def _ply(path: Path, points, faces) -> Path:
    header = [
        "ply", "format ascii 1.0", f"element vertex {len(points)}",
        "property float x", "property float y", "property float z",
        f"element face {len(faces)}", "property list uchar int vertex_indices", "end_header",
    ]  # fmt: skip
    body = [" ".join(map(str, p)) for p in points] + ["3 " + " ".join(map(str, f)) for f in faces]
    path.write_text("\n".join([*header, *body, ""]))
    return path


@pytest.mark.parametrize(
    ("name", "message"),
    [
        ("nan.stl", "has a coordinate that is not a finite number"),
        ("minus-one.ply", "names vertex -1, which does not exist"),
        ("too-far.ply", "names vertex 99, which does not exist"),
    ],
)
def test_a_broken_surface_is_a_one_line_error_and_no_crash(tmp_path, name, message):
    points = list(SQUARE)
    faces = list(FACES)
    if name == "nan.stl":
        points[4] = (5, float("nan"), 8)
        mesh = _stl(tmp_path / name, points, faces)
    else:
        faces[2] = (2, 3, -1 if name == "minus-one.ply" else 99)
        mesh = _ply(tmp_path / name, points, faces)
    env = {**os.environ, "VASCSIM_HOME": str(tmp_path / "home")}
    env.pop("VASCSIM_DATABASE_URL", None)
    args = ["tasks", "add", "t", "--mesh", str(mesh), "--thickness", "1.5", "--entry", "5,5,10"]
    done = subprocess.run([VASCSIM, *args], env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 1, (done.returncode, done.stderr[-2000:])
    assert message in done.stderr and len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert not (tmp_path / "home" / "tasks" / "t").exists()


# -- seen 7: tetrahedral meshes `tasks add` took and `run` could not use ------------------------------


def _box(scale: float = 1.0, sets=("end0", "end1")):
    """A 10 x 10 x 1.5 mm wall on 1 mm cells (x 0.5 mm through it), its x ends named ``sets``."""
    from sim.mesh import TetMesh, grid_box_mesh

    box = grid_box_mesh(np.linspace(0, 0.01, 11), np.linspace(0, 0.01, 11), np.linspace(0, 0.0015, 4))
    named = {new: box.node_sets[old] for new, old in zip(sets, ("x0", "x1"), strict=False)}
    return TetMesh(box.points * scale, box.tets, box.regions, node_sets=named)


def _vtu(path: Path, mesh, regions=None) -> Path:
    import meshio

    point_data = {}
    for name, ids in mesh.node_sets.items():
        flags = np.zeros(mesh.n_nodes, dtype=np.uint8)
        flags[ids] = 1
        point_data[f"set:{name}"] = flags
    labels = mesh.regions if regions is None else regions
    meshio.write(
        path,
        meshio.Mesh(
            mesh.points, [("tetra", mesh.tets)], point_data=point_data, cell_data={"region": [labels]}
        ),
    )
    return path


def _single_tet(path: Path, held: int) -> Path:
    import meshio

    points = np.array([[0, 0, 0], [0.004, 0, 0], [0, 0.004, 0], [0, 0, 0.004]], dtype=float)
    flags = np.zeros(4, dtype=np.uint8)
    flags[:held] = 1
    point_data = {"set:end0": flags} if held else {}
    meshio.write(path, meshio.Mesh(points, [("tetra", np.array([[0, 1, 2, 3]]))], point_data=point_data))
    return path


def _tet_cases(folder: Path) -> dict[str, tuple[Path, str, str]]:
    """name -> (mesh file, --entry in mm, the one line the refusal must contain)."""
    box = _box()
    labels = box.regions.astype(np.float64)
    nan_labels, huge_labels = labels.copy(), labels.copy()
    nan_labels[7], huge_labels[11] = np.nan, 1e20
    line = _box(sets=("end0",))
    line_ids = line.node_sets["end0"][:2]
    from sim.mesh import TetMesh

    on_a_line = TetMesh(line.points, line.tets, node_sets={"end0": line_ids})
    return {
        "single-tet-held-on-nothing": (_single_tet(folder / "a.vtu", 0), "1,1,4", "no node set to hold"),
        "single-tet": (_single_tet(folder / "b.vtu", 3), "1,1,3", "free outer-surface node(s)"),
        "no-end-sets": (_vtu(folder / "c.vtu", _box(sets=())), "5,5,1.5", "no node set to hold"),
        "tiny": (_vtu(folder / "d.vtu", _box(scale=1e-30)), "0,0,0", "spans 1.42e-32 m corner to corner"),
        "nan-region": (
            _vtu(folder / "e.vtu", box, nan_labels),
            "5,5,1.5",
            "tetrahedron 7 has region label nan",
        ),
        "huge-region": (_vtu(folder / "f.vtu", box, huge_labels), "5,5,1.5", "region label 1e+20"),
        "held-on-a-line": (_vtu(folder / "g.vtu", on_a_line), "5,5,1.5", "node(s) on one line"),
        "entry-far-away": (_vtu(folder / "h.vtu", box), "50,5,1.5", "the entry point is 40 mm from"),
        "good": (
            _vtu(folder / "i.vtu", box),
            "5,5,1.5",
            "task good added: one bite at (5.00, 5.00, 1.50) mm",
        ),
    }


def test_a_tet_mesh_run_cannot_use_is_refused_in_one_line(tmp_path):
    """Each bad mesh is refused by `vascsim tasks add` with exit 1 and exactly one stderr line (no
    traceback, no numpy or meshio warning); the good control is added."""
    cases = _tet_cases(tmp_path)
    env = {**os.environ, "VASCSIM_HOME": str(tmp_path / "home")}
    env.pop("VASCSIM_DATABASE_URL", None)
    running = {
        name: subprocess.Popen(
            [VASCSIM, "tasks", "add", name, "--mesh", str(path), "--entry", entry],
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for name, (path, entry, _) in cases.items()
    }
    done = {name: (process.communicate(timeout=300), process.returncode) for name, process in running.items()}
    for name, ((out, err), returncode) in done.items():
        message = cases[name][2]
        if name == "good":
            assert returncode == 0 and message in out, (out, err)
            continue
        assert returncode == 1, (name, returncode, err)
        assert message in err and len(err.strip().splitlines()) == 1, (name, err)
        assert not (tmp_path / "home" / "tasks" / name).exists()


def test_a_run_whose_set_up_fails_leaves_nothing_behind(tmp_path, catalog_url):
    """A stored task whose mesh was replaced by hand after `tasks add` (no held ends now): `vascsim
    run` refuses it in one line and leaves no catalogue row, session folder, journal or ring (the
    row was left `running`, with its journals and a 19 MB ring in /dev/shm)."""
    import sqlalchemy

    home = tmp_path / "home"
    env = {**os.environ, "VASCSIM_HOME": str(home), "VASCSIM_DATABASE_URL": catalog_url}

    def vascsim(*args):
        return subprocess.run([VASCSIM, *args], env=env, capture_output=True, text=True, timeout=300)

    added = vascsim(
        "tasks", "add", "t6", "--mesh", str(_vtu(tmp_path / "t.vtu", _box())), "--entry", "5,5,1.5"
    )
    assert added.returncode == 0, added.stderr
    _vtu(home / "tasks" / "t6" / "mesh.vtu", _box(sets=()))  # edited by hand: held on nothing
    assert vascsim("studies", "add", "s").returncode == 0
    assert vascsim("participants", "add", "P1", "--study", "s").returncode == 0
    rings = set(Path("/dev/shm").glob("vascsim-ring-*"))
    ran = vascsim("run", "--study", "s", "--participant", "P1", "--task", "t6", "--device", "scripted")
    *notes, error = ran.stderr.strip().splitlines()
    assert ran.returncode == 1 and all(line.startswith("note: ") for line in notes), ran.stderr
    assert error == "vascsim: error: the mesh has no node set end0, end1; its sets: none", ran.stderr
    engine = sqlalchemy.create_engine(catalog_url.replace("postgresql://", "postgresql+psycopg://"))
    try:
        with engine.connect() as db:
            assert db.execute(sqlalchemy.text("select count(*) from sessions")).scalar() == 0
    finally:
        engine.dispose()
    assert not (home / "sessions").exists() or not any((home / "sessions").iterdir())
    assert not orphaned(set(Path("/dev/shm").glob("vascsim-ring-*")) - rings)


def orphaned(rings: set[Path]) -> set[Path]:
    """The rings no live process has mapped: a recording left them behind (the other test worker's
    sessions make rings of their own meanwhile, mapped while they record)."""
    mapped = set()
    for maps in Path("/proc").glob("[0-9]*/maps"):
        try:
            lines = maps.read_text().splitlines()
            mapped.update(line.split()[-1] for line in lines if "vascsim-ring-" in line)
        except OSError:  # the process ended while it was read
            continue
    return {ring for ring in rings if ring.exists() and str(ring) not in mapped}


def test_an_unreadable_mesh_file_is_one_line_without_the_readers_chatter(tmp_path):
    """meshio printed a blank line and "Error: Couldn't read file" before our error; VTK's STL reader
    logged 20 lines of ERROR:root and a warning. The user gets one line, on stderr, and no stdout."""
    files = {
        "garbage.vtu": (b"garbage", "could not be read: not a readable mesh of this format"),
        "empty.msh": (b"$MeshFormat\n2.2 0 8\n$EndMeshFormat\n", "has no linear tetrahedra"),
        "random.stl": (bytes(range(256)) + bytes(44), "surface file"),
    }
    env = {**os.environ, "VASCSIM_HOME": str(tmp_path / "home")}
    env.pop("VASCSIM_DATABASE_URL", None)
    for name, (content, message) in files.items():
        (tmp_path / name).write_bytes(content)
        args = ["tasks", "add", "zz", "--mesh", str(tmp_path / name), "--thickness", "1", "--entry", "0,0,0"]
        done = subprocess.run([VASCSIM, *args], env=env, capture_output=True, text=True, timeout=300)
        assert done.returncode == 1 and done.stdout == "", (name, done.stdout)
        assert len(done.stderr.splitlines()) == 1 and message in done.stderr, (name, done.stderr)
