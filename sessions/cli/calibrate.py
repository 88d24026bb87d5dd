"""`vascsim calibrate`: a bench camera's intrinsics from photos of a ChArUco board."""

from __future__ import annotations

import click

from sessions.cli.base import (
    existing_path,
    number_pair,
    user_errors,
)


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

    from metrics.errors import MetricsError
    from sim.tracking.camera import BoardSpec, calibrate_charuco

    frames = []
    for path in images:
        existing_path(path, "board photo")
        image = cv2.imread(path, cv2.IMREAD_GRAYSCALE)
        if image is None:
            raise MetricsError(f"{path} is not an image OpenCV can read")
        frames.append(image)
    board = BoardSpec(number_pair(squares, "--squares"), square_mm / 1e3, marker_mm / 1e3, dictionary)
    camera = calibrate_charuco(frames, board)
    camera.save(out)
    click.echo(
        f"calibration: {out} (reprojection error {camera.rms:.3f} px, focal {camera.matrix[0, 0]:.1f} px)"
    )
