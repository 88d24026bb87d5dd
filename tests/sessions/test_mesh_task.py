"""A task on your own vessel geometry: `vascsim tasks add --mesh` meshes a lumen surface, stores the
task in the data directory, lists and shows it, and `vascsim run` records and scores a session on it."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from sessions.cli import main
from tests.sim.test_surface_mesh import tube_surface


@pytest.fixture
def home(tmp_path, monkeypatch):
    folder = tmp_path / "home"
    monkeypatch.setenv("VASCSIM_HOME", str(folder))
    monkeypatch.delenv("VASCSIM_DATABASE_URL", raising=False)
    return folder


def _ok(*args):
    result = CliRunner().invoke(main, list(args))
    assert result.exit_code == 0, result.output
    return result


def test_a_task_added_from_a_surface_runs_and_scores(home, tmp_path):
    tube_surface(4.0, 12.0, 96, 24).save(tmp_path / "lumen.stl")
    added = _ok(
        "tasks",
        "add",
        "my-artery",
        "--mesh",
        str(tmp_path / "lumen.stl"),
        "--thickness",
        "1.5",
        "--entry",
        "5.5,0,6",
        "--max-edge",
        "0.5",
    )
    lines = added.stdout.splitlines()
    assert lines[0].endswith("meshed by TetGen") and "radius-edge ratio" in lines[1]
    assert lines[-1].startswith("task my-artery added: one bite at (5.50, 0.00, 6.00) mm, held on end0, end1")
    assert (home / "tasks" / "my-artery" / "mesh.vtu").is_file()
    listed = json.loads(_ok("tasks", "list", "--json").stdout)
    assert "my-artery" in {row["task"] for row in listed} and "interrupted-stitch" in {
        row["task"] for row in listed
    }
    shown = json.loads(_ok("tasks", "show", "my-artery", "--json").stdout)
    assert shown["scenario"] == "mesh_file" and shown["normal"] == pytest.approx([1.0, 0.0, 0.0], abs=0.05)
    _ok("studies", "add", "own")
    _ok("participants", "add", "P1", "--study", "own")
    ran = json.loads(
        _ok("run", "--study", "own", "--participant", "P1", "--task", "my-artery", "--json").stdout
    )
    peak = ran["metrics"]["peak_force"]
    assert 0.3 < peak < 3.0  # the calibrated wall's puncture range, on a mesh this task brought


def test_a_bad_task_is_refused_and_nothing_is_written(home, tmp_path):
    tube_surface(4.0, 10.0, 32, 8).save(tmp_path / "lumen.stl")
    runner = CliRunner()
    base = ["tasks", "add", "x1", "--mesh", str(tmp_path / "lumen.stl"), "--entry", "5.5,0,5"]
    for extra, message in (
        (["--thickness", "1", "--tissue", "marble"], "marble"),
        ([], "a wall thickness (m) is needed"),
        (["--thickness", "1", "--entry", "a,b"], "is not X,Y,Z"),
    ):
        refused = runner.invoke(main, [*base, *extra])
        assert refused.exit_code in (1, 2) and message in refused.output, refused.output
    assert not (home / "tasks" / "x1").exists()
    _ok(*base, "--thickness", "1", "--max-edge", "1")
    again = runner.invoke(main, [*base, "--thickness", "1", "--max-edge", "1"])
    assert again.exit_code == 1 and "task 'x1' already exists" in again.output
    clash = runner.invoke(
        main,
        [
            "tasks",
            "add",
            "wall-stitch",
            "--mesh",
            str(tmp_path / "lumen.stl"),
            "--thickness",
            "1",
            "--entry",
            "5,0,5",
        ],
    )
    assert clash.exit_code == 1 and "already exists" in clash.output
