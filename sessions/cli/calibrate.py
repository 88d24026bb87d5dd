"""`vascsim calibrate`: a camera's intrinsics from a ChArUco board, from photos or live from the camera."""

from __future__ import annotations

import click

from sessions.cli.base import (
    existing_path,
    number_pair,
    open_catalog,
    user_errors,
)


@click.command()
@click.argument("images", nargs=-1)
@click.option("--live", is_flag=True, help="Calibrate from the camera's own frames, guided view by view.")
@click.option(
    "--table", is_flag=True,
    help="Register the table: how the (calibrated) camera sits over it, from the board lying flat on it.",
)  # fmt: skip
@click.option(
    "--source", default="camera:0", show_default=True,
    help="With --live or --table: camera:INDEX, a stream URL, or a video file of the board.",
)  # fmt: skip
@click.option(
    "-o", "--out", type=click.Path(dir_okay=False),
    help="Calibration JSON to write (default with --live: this station's, in the data directory).",
)  # fmt: skip
@click.option("--squares", default="7x5", show_default=True, help="ChArUco board squares, COLUMNSxROWS.")
@click.option("--square-mm", default=30.0, show_default=True, type=click.FloatRange(min=1.0))
@click.option("--marker-mm", default=22.0, show_default=True, type=click.FloatRange(min=1.0))
@click.option("--dictionary", default="DICT_4X4_50", show_default=True, help="ArUco dictionary of the board.")
@click.option(
    "--timeout", default=180.0, show_default=True, type=click.FloatRange(min=5.0),
    help="With --live: give up after this many seconds.",
)  # fmt: skip
@click.option(
    "--view", type=click.Choice(["window", "none"]), default=None,
    help="With --live: show the camera's picture, the views still to take and which way to turn the "
    "board next in a window [default: window where a display exists, else none: the terminal says it].",
)  # fmt: skip
@user_errors
def calibrate(
    images, live, table, source, out, squares, square_mm, marker_mm, dictionary, timeout, view
) -> None:
    """Calibrate a camera from views of a ChArUco board (square-on and tilted each way).

    From photos: IMAGES are 10-20 photos of the board; --out names the JSON to write
    (for `vascsim import-video --camera`). Live (--live): hold the board in front of
    the camera and turn it as the window (or, with no display, the progress line) asks
    (square-on, tilted left, right, up, down): the window shows the camera's picture with
    the board's corners, the views taken of each kind and which way to turn the board
    next, and Esc there gives up; the fit is written as this station's calibration, which the camera
    device (`--device camera`) uses. Either way the reprojection error is reported
    (pixels), and a live fit over 1 px is refused.

    Then --table: lay the board flat on the table where you will suture, its top
    row away from you, and the camera's view is registered to it, so that moving
    the instrument over the table moves the needle over the wall as the screen
    shows it (without it the camera is taken to be on the monitor, facing you).
    """
    from pathlib import Path

    from sim.tracking.camera import BoardSpec

    board = BoardSpec(number_pair(squares, "--squares"), square_mm / 1e3, marker_mm / 1e3, dictionary)
    if table:
        from sessions.running.camera import register_table

        _, home = open_catalog()
        _, error, path = register_table(source, home, board)
        click.echo(
            f"table registered: {path} (the board's reprojection error {error:.2f} px; lower is better)"
        )
        return
    if live:
        if images:
            raise click.UsageError("give either board photos or --live, not both")
        _calibrate_live(source, board, Path(out) if out else None, timeout, view)
        return
    if not images or not out:
        raise click.UsageError("give board photos and --out, or calibrate from the camera with --live")
    import cv2

    from sim.errors import TrackingError
    from sim.tracking.camera import calibrate_charuco

    frames = []
    for path in images:
        existing_path(path, "board photo")
        image = cv2.imread(path, cv2.IMREAD_GRAYSCALE)
        if image is None:
            raise TrackingError(f"{path} is not an image OpenCV can read")
        frames.append(image)
    camera = calibrate_charuco(frames, board)
    camera.save(out)
    click.echo(
        f"calibration: {out} (reprojection error {camera.rms:.3f} px, focal {camera.matrix[0, 0]:.1f} px)"
    )


def _calibrate_live(source: str, board, out, timeout: float, view: str | None) -> None:
    from sessions.cli.station import chosen_view
    from sessions.running.camera import calibrate_live

    if chosen_view(view) == "window":
        from sessions.running.calibration_window import CalibrationWindow

        window = CalibrationWindow()
    else:
        window = None

    _, home = open_catalog()
    shown = {"last": None}

    def progress(kept, missing) -> None:
        if kept is not None:
            click.echo(f"  kept a view: {kept}", err=True)
        line = "all views taken" if not missing else "still to show: " + ", ".join(missing)
        if line != shown["last"]:
            click.echo(line, err=True)
            shown["last"] = line

    try:
        camera, path = calibrate_live(source, home, board, out, progress, timeout, window)
    finally:
        if window is not None:
            window.close()
    click.echo(
        f"calibration: {path} (reprojection error {camera.rms:.3f} px, focal {camera.matrix[0, 0]:.1f} px, "
        f"{camera.size[0]}x{camera.size[1]})"
    )
