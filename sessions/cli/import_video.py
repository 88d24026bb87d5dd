"""`vascsim import-video`: a bench-model session from video, the needle holder tracked by its marker."""

from __future__ import annotations

import click

from sessions.cli.base import (
    existing_path,
    number_pair,
    open_catalog,
    print_json,
    progress_bar,
    user_errors,
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
@click.option(
    "--instrument", type=click.Choice(["needle-holder", "forceps"]), default=None,
    help="Track this instrument's marker cube (its registered tip) instead of one flat marker.",
)  # fmt: skip
@click.option("--json", "as_json", is_flag=True, help="Print the session's metrics as JSON.")
@user_errors
def import_video(
    video, camera_file, study, participant, marker_id, marker_mm, tip_offset_mm, instrument, as_json
) -> None:
    """Add a bench-model session from video: ArUco tracking of the needle holder.

    The marker's pose (sub-pixel corners, solvePnP) gives the instrument tip in
    every frame; the smoothed path becomes a session of the study with the same
    motion metrics as simulator sessions (no force or tissue metrics).
    """
    from sessions.exchange.importing import import_bench_video
    from sim.tracking.markers import MarkerBody

    existing_path(video, "video")
    existing_path(camera_file, "camera calibration")
    offset = tuple(v / 1e3 for v in number_pair(tip_offset_mm, "--tip-offset-mm", float, 3))
    catalog, home = open_catalog()
    if instrument is not None:  # the cube the camera device tracks, the same detector and pose
        from sessions.running.camera import instrument_body

        marker = instrument_body(home, instrument)
    else:
        marker = MarkerBody.flat(marker_id, marker_mm / 1e3, offset)
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
