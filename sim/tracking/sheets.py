"""Printable marker sheets: each instrument's cube as a net to cut, fold and glue, at true scale.

The page is drawn at exactly 24 pixels a millimetre (609.6 dots an inch), so every marker cell (4 mm
on the default 24 mm markers) is a whole number of pixels and nothing is resampled. The PNG says its
resolution (24,000 pixels a metre in its ``pHYs`` chunk) and the PDF page is A4 (210 x 297 mm) with
the image filling it, so either prints at true size when printed at 100 % ("actual size", not "fit
to page"). A 50 mm bar on the sheet checks the print with a ruler.

Each net is the cube's four side faces in a band (``+z``, ``+x``, ``-z``, ``-x`` from left to right,
each marker upright, the instrument's tip below) and the back-end face (``+y``) above the first,
with a glue tab; the face where the shaft passes (``-y``) is left open.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from sim.errors import TrackingError
from sim.tracking.camera import aruco_dictionary
from sim.tracking.markers import MarkerBody

PIXELS_PER_MM = 24
DPI = PIXELS_PER_MM * 25.4
PAGE_MM = (210, 297)  # A4, portrait
MARGIN_MM = 15
SCALE_BAR_MM = 50
TAB_MM = 8


def _mm(value: float) -> int:
    return int(round(value * PIXELS_PER_MM))


def marker_sheet(bodies: list[MarkerBody]) -> NDArray[np.uint8]:
    """The sheet (grey, H x W) with a net per instrument, top to bottom, and the scale bar."""
    import cv2

    width, height = _mm(PAGE_MM[0]), _mm(PAGE_MM[1])
    page = np.full((height, width), 255, np.uint8)
    y = MARGIN_MM
    _text(page, "vascsim instrument markers - print at 100 % (actual size), then check the bar", MARGIN_MM, y)
    y += 8
    cv2.rectangle(page, (_mm(MARGIN_MM), _mm(y)), (_mm(MARGIN_MM + SCALE_BAR_MM), _mm(y + 3)), 0, -1)
    _text(page, f"{SCALE_BAR_MM} mm", MARGIN_MM + SCALE_BAR_MM + 3, y + 3)
    y += 12
    for body in bodies:
        if body.cube_m <= 0:
            raise TrackingError(f"instrument {body.name!r} is a flat marker, not a cube; no net to print")
        cube = body.cube_m * 1e3
        if y + 2 * cube + 14 > PAGE_MM[1] - MARGIN_MM:
            raise TrackingError(f"{len(bodies)} instruments do not fit on one A4 sheet; print them in turns")
        ids = ", ".join(str(i) for i in body.ids)
        _text(page, f"{body.name}: {cube:.0f} mm cube, markers {ids} ({body.dictionary})", MARGIN_MM, y + 4)
        y += 8
        _draw_net(page, body, MARGIN_MM, y)
        y += 2 * cube + 10
    return page


def _draw_net(page: NDArray[np.uint8], body: MarkerBody, left_mm: float, top_mm: float) -> None:
    import cv2

    cube = body.cube_m * 1e3
    faces = {face.marker_id: face for face in body.faces}
    band = [body.faces[k].marker_id for k in range(4)]  # +z, +x, -z, -x
    origins = [(left_mm + k * cube, top_mm + cube) for k in range(4)]
    origins.append((left_mm, top_mm))  # the back end (+y), above the first side face
    for marker_id, (x, y) in zip([*band, body.faces[4].marker_id], origins, strict=True):
        _draw_face(page, body, faces[marker_id].marker_id, x, y)
        cv2.rectangle(page, (_mm(x), _mm(y)), (_mm(x + cube), _mm(y + cube)), 170, 1)
    tab_left = left_mm + 4 * cube
    tab = np.array(
        [[tab_left, top_mm + cube], [tab_left + TAB_MM, top_mm + cube + 3],
         [tab_left + TAB_MM, top_mm + 2 * cube - 3], [tab_left, top_mm + 2 * cube]]
    )  # fmt: skip
    cv2.polylines(page, [(tab * PIXELS_PER_MM).round().astype(np.int32)], True, 170, 1)
    _text(page, "glue", tab_left + 1, top_mm + 1.5 * cube, scale=0.6)
    _text(page, "tip this way (shaft through the open face)", left_mm, top_mm + 2 * cube + 5, scale=0.7)


def _draw_face(page: NDArray[np.uint8], body: MarkerBody, marker_id: int, x_mm: float, y_mm: float) -> None:
    import cv2

    side = _mm(body.side_m * 1e3)
    cells = aruco_dictionary(body.dictionary).markerSize + 2
    if side % cells:
        raise TrackingError(
            f"a {body.side_m * 1e3:g} mm marker of {cells} cells is not a whole number of pixels a cell at "
            f"{PIXELS_PER_MM} px/mm; choose a side that is a multiple of {cells / PIXELS_PER_MM:g} mm"
        )
    image = cv2.aruco.generateImageMarker(aruco_dictionary(body.dictionary), marker_id, side)
    inset = (body.cube_m - body.side_m) * 1e3 / 2
    top, left = _mm(y_mm + inset), _mm(x_mm + inset)
    page[top : top + side, left : left + side] = image


def _text(page: NDArray[np.uint8], words: str, x_mm: float, y_mm: float, scale: float = 1.0) -> None:
    import cv2

    cv2.putText(page, words, (_mm(x_mm), _mm(y_mm)), cv2.FONT_HERSHEY_SIMPLEX, 2.2 * scale, 0, 3, cv2.LINE_AA)


def write_marker_sheet(bodies: list[MarkerBody], path: str | Path) -> Path:
    """Write the sheet as PNG (``.png``) or PDF (``.pdf``), at true scale."""
    from PIL import Image

    path = Path(path)
    image = Image.fromarray(marker_sheet(bodies))
    if path.suffix.lower() == ".png":
        image.save(path, dpi=(DPI, DPI))
    elif path.suffix.lower() == ".pdf":
        image.save(path, "PDF", resolution=DPI)
    else:
        raise TrackingError(f"a marker sheet is written as .png or .pdf, not {path.suffix or 'no suffix'!r}")
    return path
