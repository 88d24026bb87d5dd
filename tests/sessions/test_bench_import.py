"""Bench-model sessions in the catalog: `vascsim import-video` tracks, stores and scores them."""

import json

import pytest
from click.testing import CliRunner


@pytest.mark.slow
def test_import_video_into_a_study(bench_calibration, bench_video, home):
    from sessions.cli import main

    _, camera_file = bench_calibration
    path, _, _ = bench_video

    def invoke(*args):
        return CliRunner().invoke(main, list(args))

    assert invoke("studies", "add", "bench").exit_code == 0
    assert invoke("participants", "add", "B1", "--study", "bench", "--level", "trainee").exit_code == 0
    result = invoke("import-video", str(path), "--camera", str(camera_file), "--study", "bench",
                    "--participant", "B1", "--json")  # fmt: skip
    assert result.exit_code == 0, result.output
    imported = json.loads(result.stdout)
    assert imported["metrics"]["path_length"] > 0.3
    shown = json.loads(invoke("sessions", "show", imported["session"], "--json").stdout)
    assert shown["device"] == "bench-video" and {f["name"] for f in shown["files"]} == {
        "track.parquet",
        "camera.json",
    }
    rescored = json.loads(invoke("score", imported["session"], "--json").stdout)
    assert rescored[imported["session"]]["path_length"] == imported["metrics"]["path_length"]
    unknown = invoke(
        "import-video", str(path), "--camera", str(camera_file), "--study", "bench", "--participant", "X"
    )
    assert (
        unknown.exit_code == 1 and "no participant 'X'" in unknown.output and unknown.output.count("\n") == 1
    )
    no_replay = invoke("replay", imported["session"])
    assert no_replay.exit_code == 1 and "no 3-D scene to replay" in no_replay.output
