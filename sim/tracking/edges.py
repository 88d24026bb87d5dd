"""A marker body's pose refined on every black-white edge of its markers' cells, not only their corners.

A marker seen alone gives its tilt from the foreshortening of one small square. Four corners (each the
meeting point of two fitted outer edges, :func:`sim.tracking.pose.refined_corners`) measure it poorly
when the square is small in the image: at 640x480 a 24 mm marker at 30 cm is 46 px across, and a
tilt error of a third of a degree moves a tip 120 mm away by 0.7 mm, mostly in depth. The marker's
inner cells carry the same information many times over: a 4x4 ArUco marker with its black border is a
6x6 grid, and every grid segment between a black and a white cell (about 40 of them, outer border
included) is an edge at a known place on the face.

Refinement: each such segment is projected with the starting pose; across it, at
:data:`SAMPLES_ALONG` points, the image's edge is located as the centroid of the intensity rising from
the dark cell to the bright one (within :data:`REACH_OF_CELL` of a cell, so a neighbouring edge is never
reached); then Gauss-Newton on the body's six pose parameters minimises the located points' distances
to their projected segments (Huber-weighted, Jacobian from ``cv2.projectPoints``), and the edges are
located once more from the refined pose. Measured on the synthetic wrist roll (benchmarks/camera.py,
``--part accuracy``): the tip's RMS error 1.28 -> 0.93 mm at 640x480 (frames with one marker seen
1.45 -> 1.09 mm), for about 2 ms more a frame; at 1280x720, where the markers are 92 px across, 0.43 ->
0.39 mm, too little for its cost, so the tracker refines only markers seen smaller
(:data:`sim.tracking.pose.EDGES_BELOW_PX`).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from sim.tracking.camera import Camera, aruco_dictionary
from sim.tracking.markers import MarkerBody

SAMPLES_ALONG = np.linspace(0.2, 0.8, 7)
"""Where along each cell edge (fractions of it) the image's edge is located: away from the grid's
corners, where a crossing edge blurs into it."""
REACH_OF_CELL = 0.3
"""How far across a projected edge its image is looked for, as a fraction of the cell's side in the
image (at most :data:`MAX_REACH_PX`): under half a cell, so the next edge is never found instead."""
MAX_REACH_PX = 3.0
PROFILE_STEPS = 25
"""Points of each intensity profile across an edge."""
MIN_EDGE_PX = 4.0
"""A cell edge shorter than this in the image is not located (it is a few blurred pixels)."""
MIN_POINTS = 24
"""Fewer located edge points than this and the starting pose is kept."""
ITERATIONS = 3
STEP_TOLERANCE = 1e-6
"""Gauss-Newton stops when no pose parameter moves more than this (rad, m; 0.1 um at the tip)."""
MEASUREMENTS = 2
"""Edges located from the starting pose, then once more from the refined one."""
HUBER_K = 1.5
"""Residuals beyond this many robust standard deviations are down-weighted (Huber)."""


@functools.cache
def cell_edges(body: MarkerBody, marker_id: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The marker's black-white cell edges in the body frame: (k, 2, 3) segment ends, and (k, 3) unit
    vectors in the face's plane pointing from each edge into its black cell. The marker's cells are its
    dictionary's bits inside a one-cell black border; outside it is the white margin."""
    import cv2

    dictionary = aruco_dictionary(body.dictionary)
    bits = cv2.aruco.Dictionary.getBitsFromByteList(
        dictionary.bytesList[marker_id].reshape(1, -1, 4), dictionary.markerSize
    )
    cells = dictionary.markerSize + 2
    grid = np.zeros((cells + 2, cells + 2), dtype=np.int8)  # with the white margin round it
    grid[0, :] = grid[-1, :] = grid[:, 0] = grid[:, -1] = 1
    grid[2:-2, 2:-2] = bits
    half, side = body.side_m / 2, body.side_m / cells
    ends, into_black = [], []
    for line in range(cells + 1):
        for cell in range(cells):
            # the line x = -half + line * side between rows; grid index offset by the margin
            left, right = grid[cell + 1, line], grid[cell + 1, line + 1]
            if left != right:
                x = -half + line * side
                ends.append([[x, half - cell * side, 0.0], [x, half - (cell + 1) * side, 0.0]])
                into_black.append([-1.0, 0.0, 0.0] if left == 0 else [1.0, 0.0, 0.0])
            above, below = grid[line, cell + 1], grid[line + 1, cell + 1]
            if above != below:
                y = half - line * side
                ends.append([[-half + cell * side, y, 0.0], [-half + (cell + 1) * side, y, 0.0]])
                into_black.append([0.0, 1.0, 0.0] if above == 0 else [0.0, -1.0, 0.0])
    face = body.faces[body.ids.index(marker_id)]
    frame = face.frame()
    segments = np.asarray(ends) @ frame.T + np.asarray(face.centre, dtype=np.float64)
    return segments, np.asarray(into_black) @ frame.T


@dataclass(frozen=True)
class EdgeSet:
    """The cell edges of some markers of a body, ready to project: ``samples`` (k * m, 3) the points
    along each edge where it is located (:data:`SAMPLES_ALONG`), ``ends`` (3k, 3) each edge's start,
    every stop, then a point just inside each edge's black cell (which way is dark)."""

    samples: NDArray[np.float64]
    ends: NDArray[np.float64]

    @property
    def count(self) -> int:
        return len(self.ends) // 3


@functools.cache
def edge_set(body: MarkerBody, marker_ids: tuple[int, ...]) -> EdgeSet:
    """The :class:`EdgeSet` of ``marker_ids`` (kept per body and set of markers)."""
    segments = np.concatenate([cell_edges(body, marker_id)[0] for marker_id in marker_ids])
    into_black = np.concatenate([cell_edges(body, marker_id)[1] for marker_id in marker_ids])
    starts, stops = segments[:, 0], segments[:, 1]
    samples = starts[:, None] + SAMPLES_ALONG[None, :, None] * (stops - starts)[:, None]
    cell = float(np.linalg.norm(stops[0] - starts[0]))  # every segment is one cell long
    ends = np.concatenate([starts, stops, starts + 0.1 * cell * into_black])
    return EdgeSet(samples.reshape(-1, 3), ends)


_STEPS = np.linspace(-1.0, 1.0, PROFILE_STEPS)


def locate_edges(
    grey: NDArray[np.uint8],
    camera: Camera,
    edges: EdgeSet,
    rvec: NDArray[np.float64],
    tvec: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Edge points located in ``grey`` near the edges projected with (rvec, tvec): their body-frame
    points (n, 3), image points (n, 2) and the image's unit normals from dark to bright (n, 2)."""
    import cv2

    nothing = np.empty((0, 3)), np.empty((0, 2)), np.empty((0, 2))
    count, along = edges.count, len(SAMPLES_ALONG)
    projected, _ = cv2.projectPoints(
        np.concatenate([edges.samples, edges.ends]), rvec, tvec, camera.matrix, camera.distortion
    )
    projected = projected.reshape(-1, 2)
    if not np.all(np.isfinite(projected)):
        return nothing
    on_edge = projected[: count * along].reshape(count, along, 2)
    start_px, stop_px, inside_px = np.split(projected[count * along :], 3)
    direction = stop_px - start_px
    length = np.hypot(direction[:, 0], direction[:, 1])
    usable = length >= MIN_EDGE_PX
    if not usable.any():
        return nothing
    on_edge, length = on_edge[usable], length[usable]
    points = edges.samples.reshape(count, along, 3)[usable]
    unit = direction[usable] / length[:, None]
    normal = np.column_stack([-unit[:, 1], unit[:, 0]])
    towards_black = np.sum(normal * (inside_px[usable] - start_px[usable]), axis=1)
    normal *= -np.sign(towards_black)[:, None]  # dark to bright
    offsets = np.minimum(MAX_REACH_PX, REACH_OF_CELL * length)[:, None] * _STEPS  # (k, s)
    samples = on_edge[:, :, None, :] + offsets[:, None, :, None] * normal[:, None, None, :]  # (k, m, s, 2)
    flat = samples.reshape(-1, PROFILE_STEPS, 2).astype(np.float32)
    # only the window the profiles cover is converted to floating point
    height, width = grey.shape[:2]
    centres = on_edge.reshape(-1, 2)
    room = MAX_REACH_PX + 2.0
    low = np.clip(np.floor(centres.min(axis=0) - room), 0, [width, height]).astype(int)
    high = np.clip(np.ceil(centres.max(axis=0) + room) + 1, 0, [width, height]).astype(int)
    if np.any(high - low < 2):
        return nothing
    window = grey[low[1] : high[1], low[0] : high[0]].astype(np.float32)
    flat -= low.astype(np.float32)
    profile = cv2.remap(window, flat[..., 0], flat[..., 1], cv2.INTER_LINEAR, borderValue=np.nan)
    rise = np.diff(profile, axis=1)
    rise = np.maximum(rise - 0.2 * np.nanmax(rise, axis=1, keepdims=True), 0.0)
    weight = rise.sum(axis=1)
    middle = np.repeat((offsets[:, 1:] + offsets[:, :-1]) / 2, along, axis=0)
    shift = (rise * middle).sum(axis=1) / np.where(weight > 0, weight, 1.0)
    found = np.isfinite(shift) & (weight > 0)
    normals = np.repeat(normal, along, axis=0)
    image_points = on_edge.reshape(-1, 2) + shift[:, None] * normals
    return points.reshape(-1, 3)[found], image_points[found], normals[found]


def refine_on_edges(
    grey: NDArray[np.uint8],
    camera: Camera,
    body: MarkerBody,
    marker_ids: list[int],
    rotation: NDArray[np.float64],
    translation: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
    """The body pose (camera <- body rotation, translation in m) refined on the cell edges of
    ``marker_ids``, starting from (rotation, translation); None when too few edges were found or the
    refinement did not stay finite."""
    import cv2

    rvec = cv2.Rodrigues(np.asarray(rotation, dtype=np.float64))[0]
    tvec = np.asarray(translation, dtype=np.float64).reshape(3, 1).copy()
    edges = edge_set(body, tuple(marker_ids))
    for _ in range(MEASUREMENTS):
        points, located, normals = locate_edges(grey, camera, edges, rvec, tvec)
        if len(points) < MIN_POINTS:
            return None
        scale = None
        for _ in range(ITERATIONS):
            projected, jacobian = cv2.projectPoints(points, rvec, tvec, camera.matrix, camera.distortion)
            residual = np.sum(normals * (projected.reshape(-1, 2) - located), axis=1)
            rows = np.einsum("ni,nij->nj", normals, jacobian[:, :6].reshape(-1, 2, 6))
            if scale is None:  # the residuals' robust spread, from where this measurement started
                scale = 1.4826 * float(np.median(np.abs(residual))) + 1e-3
            weight = np.minimum(1.0, HUBER_K * scale / np.maximum(np.abs(residual), 1e-12))
            weighted = rows * weight[:, None]
            try:
                step = np.linalg.solve(weighted.T @ rows, -(weighted.T @ residual))
            except np.linalg.LinAlgError:
                return None
            if not np.all(np.isfinite(step)):
                return None
            rvec, tvec = rvec + step[:3, None], tvec + step[3:, None]
            if float(np.abs(step).max()) < STEP_TOLERANCE:
                break
    return cv2.Rodrigues(rvec)[0], tvec.ravel()
