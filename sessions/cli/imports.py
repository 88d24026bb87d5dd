"""`vascsim calibrate`, `import-video` and `import`: data from outside the simulator."""

from __future__ import annotations

import click

from sessions.cli.base import (
    existing_path,
    open_catalog,
    print_json,
    progress_bar,
    user_errors,
)


def _pair(text: str, what: str, kind=int, count: int = 2) -> tuple:
    try:
        parts = tuple(kind(part) for part in text.replace("x", ",").split(","))
    except ValueError:
        parts = ()
    if len(parts) != count:
        raise click.BadParameter(f"{what} {text!r} needs {count} numbers separated by ',' or 'x'")
    return parts


@click.command()
@click.argument("images", nargs=-1, required=True)
@click.option(
    "-o", "--out", required=True, type=click.Path(dir_okay=False), help="Calibration JSON to write."
)
@click.option("--squares", default="7x5", show_default=True, help="ChArUco board squares, COLUMNSxROWS.")
@click.option("--square-mm", default=30.0, show_default=True, type=click.FloatRange(min=1.0))
@click.option("--marker-mm", default=22.0, show_default=True, type=click.FloatRange(min=1.0))
@click.option("--dictionary", default="DICT_4X4_50", show_default=True, help="ArUco dictionary of the board.")
@user_errors
def calibrate(images, out, squares, square_mm, marker_mm, dictionary) -> None:
    """Calibrate a bench camera from photos of a ChArUco board (10-20 views, varied tilt).

    Writes the intrinsic matrix, distortion and the reprojection error (pixels) as
    JSON, for `vascsim import-video --camera`.
    """
    import cv2

    from metrics.bench.camera import BoardSpec, calibrate_charuco
    from metrics.errors import MetricsError

    frames = []
    for path in images:
        existing_path(path, "board photo")
        image = cv2.imread(path, cv2.IMREAD_GRAYSCALE)
        if image is None:
            raise MetricsError(f"{path} is not an image OpenCV can read")
        frames.append(image)
    board = BoardSpec(_pair(squares, "--squares"), square_mm / 1e3, marker_mm / 1e3, dictionary)
    camera = calibrate_charuco(frames, board)
    camera.save(out)
    click.echo(
        f"calibration: {out} (reprojection error {camera.rms:.3f} px, focal {camera.matrix[0, 0]:.1f} px)"
    )


@click.command("import-video")
@click.argument("video")
@click.option("--camera", "camera_file", required=True,
              help="Calibration JSON from `vascsim calibrate`.")  # fmt: skip
@click.option("--study", required=True, help="Study to add the session to.")
@click.option("--participant", required=True, help="Participant code (enrolled in the study).")
@click.option("--marker-id", default=7, show_default=True, type=click.IntRange(0, 999))
@click.option(
    "--marker-mm", default=30.0, show_default=True, type=click.FloatRange(min=1.0), help="Marker side."
)
@click.option(
    "--tip-offset-mm", default="0,-60,-10", show_default=True,
    help="Instrument tip in the marker frame (x right, y up, z out of the marker), mm.",
)  # fmt: skip
@click.option("--json", "as_json", is_flag=True, help="Print the session's metrics as JSON.")
@user_errors
def import_video(
    video, camera_file, study, participant, marker_id, marker_mm, tip_offset_mm, as_json
) -> None:
    """Add a bench-model session from video: ArUco tracking of the needle holder.

    The marker's pose (sub-pixel corners, solvePnP) gives the instrument tip in
    every frame; the smoothed path becomes a session of the study with the same
    motion metrics as simulator sessions (no force or tissue metrics).
    """
    from metrics.bench.tracking import ToolMarker
    from sessions.importing import import_bench_video

    existing_path(video, "video")
    existing_path(camera_file, "camera calibration")
    offset = tuple(v / 1e3 for v in _pair(tip_offset_mm, "--tip-offset-mm", float, 3))
    marker = ToolMarker(marker_id, marker_mm / 1e3, offset)
    catalog, home = open_catalog()
    with progress_bar(transient=True) as progress:
        task = progress.add_task("tracking", total=None, last="")
        uid, values = import_bench_video(
            catalog, home, video, camera_file, study, participant, marker,
            lambda done: progress.update(task, completed=done, last=f"frame {done}"),
        )  # fmt: skip
    if as_json:
        print_json({"session": uid, "metrics": values})
    else:
        click.echo(f"imported bench session {uid} for {participant} in study {study}")


@click.command("import")
@click.argument("kinematics_dir")
@click.argument("meta_file")
@click.option("--study", required=True, help="Study to import into (created if missing).")
@user_errors
def import_jigsaws(kinematics_dir: str, meta_file: str, study: str) -> None:
    """Import a JIGSAWS task (kinematics folder + meta file) as a scored study.

    Surgeons become participants (labels novice/intermediate/expert from the
    self-reported level; GRS totals stored as ratings); trials become sessions
    whose files are the kinematics files, with checksums.
    """
    from sessions.importing import import_jigsaws as run_import

    existing_path(kinematics_dir, "kinematics folder", folder=True)
    existing_path(meta_file, "meta file")
    catalog, _ = open_catalog()
    count = run_import(catalog, kinematics_dir, meta_file, study)
    click.echo(f"imported {count} JIGSAWS trial(s) into study {study}")
