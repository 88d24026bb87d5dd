"""Hostile input, round 3 (issue 45, seen 6): a surface with a NaN vertex crashed `vascsim tasks add`
with SIGSEGV inside TetGen; a PLY face naming vertex -1 printed an IndexError traceback. Both are
now one-line errors naming the element, and the mesher never sees them. Run as a separate process:
a crash must fail this test, not end the test run."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

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
    assert message in done.stderr and "Traceback" not in done.stderr, done.stderr
    assert not (tmp_path / "home" / "tasks" / "t").exists()
