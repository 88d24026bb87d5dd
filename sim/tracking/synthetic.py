"""Synthetic video with a known camera and known instrument motion, to test the tracker.

Planar textures (an instrument's markers, a ChArUco board) are drawn into frames through
the exact homography of the pinhole camera, supersampled 4x inside the region they cover
and averaged down, over a textured background with sensor noise. A marker body's faces
that turn away from the camera are not drawn (a convex body hides nothing else). Motion
blur averages sub-frame renders over the exposure; an occluder (a hand passing in front)
covers the instrument in given spans. The ground-truth poses are returned with the
video, so tracking error is measured, not assumed.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from sim.tracking.camera import BoardSpec, aruco_dictionary
from sim.tracking.markers import MarkerBody, MarkerFace

SUPERSAMPLE = 4


def default_camera_matrix(
    size: tuple[int, int] = (1920, 1080), focal_px: float = 1400.0
) -> NDArray[np.float64]:
    width, height = size
    return np.array([[focal_px, 0.0, (width - 1) / 2], [0.0, focal_px, (height - 1) / 2], [0.0, 0.0, 1.0]])


def background(size: tuple[int, int], rng: np.random.Generator) -> NDArray[np.uint8]:
    """A mottled grey bench surface (smooth noise), (H, W) uint8."""
    import cv2

    width, height = size
    coarse = rng.normal(150, 25, size=(height // 40 + 2, width // 40 + 2)).astype(np.float32)
    return np.clip(cv2.resize(coarse, (width, height), interpolation=cv2.INTER_CUBIC), 40, 230).astype(
        np.uint8
    )


def draw_plane(
    frame: NDArray[np.uint8],
    texture: NDArray[np.uint8],
    plane_corners: NDArray[np.float64],
    rotation: NDArray[np.float64],
    translation: NDArray[np.float64],
    camera_matrix: NDArray[np.float64],
) -> None:
    """Draw ``texture`` (grey) onto ``frame`` in place: its corners (top-left, top-right, bottom-right,
    bottom-left) are ``plane_corners`` (4, 3) in the plane's frame, posed by (rotation, translation)."""
    import cv2

    points = plane_corners @ rotation.T + translation
    projected = points @ camera_matrix.T
    image = projected[:, :2] / projected[:, 2:3]
    height, width = frame.shape
    low = np.maximum(np.floor(image.min(axis=0)) - 2, 0).astype(int)
    high = np.minimum(np.ceil(image.max(axis=0)) + 2, [width, height]).astype(int)
    if np.any(high <= low):
        return
    th, tw = texture.shape
    # pixel centres are at integer coordinates: a texture's outer edges are half a pixel outside them
    source = np.array([[0, 0], [tw, 0], [tw, th], [0, th]], dtype=np.float32) - 0.5
    # into a supersampled window over the covered region, then averaged down (no aliasing); output pixel
    # x covers supersampled pixels [S x, S x + S), whose centre is S x + (S - 1) / 2
    target = ((image - low) * SUPERSAMPLE + (SUPERSAMPLE - 1) / 2).astype(np.float32)
    homography = cv2.getPerspectiveTransform(source, target)
    window = (int(high[0] - low[0]) * SUPERSAMPLE, int(high[1] - low[1]) * SUPERSAMPLE)
    drawn = cv2.warpPerspective(texture, homography, window, flags=cv2.INTER_LINEAR, borderValue=0)
    mask = cv2.warpPerspective(np.full_like(texture, 255), homography, window, flags=cv2.INTER_LINEAR)
    size = (int(high[0] - low[0]), int(high[1] - low[1]))
    drawn = cv2.resize(drawn, size, interpolation=cv2.INTER_AREA).astype(np.float32)
    alpha = cv2.resize(mask, size, interpolation=cv2.INTER_AREA).astype(np.float32) / 255.0
    region = frame[low[1] : high[1], low[0] : high[0]].astype(np.float32)
    frame[low[1] : high[1], low[0] : high[0]] = np.clip(alpha * drawn + (1 - alpha) * region, 0, 255).astype(
        np.uint8
    )


def face_texture(
    body: MarkerBody, face: MarkerFace, pixels: int = 480
) -> tuple[NDArray[np.uint8], NDArray[np.float64]]:
    """One face's texture, the marker on white (a quarter side of quiet zone on a flat marker, the
    whole cube face on a cube), and that texture's corners in the body frame (m)."""
    import cv2

    inner = cv2.aruco.generateImageMarker(aruco_dictionary(body.dictionary), face.marker_id, pixels)
    half_m = body.cube_m / 2 if body.cube_m > 0 else body.side_m * 0.75
    border = int(round(pixels * (half_m / body.side_m - 0.5)))
    texture = cv2.copyMakeBorder(inner, border, border, border, border, cv2.BORDER_CONSTANT, value=255)
    h = body.side_m * (0.5 + border / pixels)
    local = np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])
    return texture, local @ face.frame().T + np.asarray(face.centre, dtype=float)


def draw_body(
    frame: NDArray[np.uint8],
    textures: list[tuple[NDArray[np.uint8], NDArray[np.float64]]],
    rotation: NDArray[np.float64],
    translation: NDArray[np.float64],
    camera_matrix: NDArray[np.float64],
) -> None:
    """Draw the faces of a body posed by (rotation, translation) that face the camera."""
    for texture, corners in textures:
        centre = corners.mean(axis=0)
        normal = np.cross(corners[3] - corners[0], corners[1] - corners[0])  # out of the face
        if np.dot(rotation @ normal, rotation @ centre + translation) < 0:
            draw_plane(frame, texture, corners, rotation, translation, camera_matrix)


def rotation_xyz(angles: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rotation matrix from angles (rad) about x, then y, then z."""
    ax, ay, az = angles
    cx, sx, cy, sy, cz, sz = np.cos(ax), np.sin(ax), np.cos(ay), np.sin(ay), np.cos(az), np.sin(az)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx


FACING_CAMERA = np.diag([1.0, -1.0, -1.0])
"""A plane whose z axis points back at the camera (camera looks along +z, image y down)."""


def suturing_motion(time: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """A needle-holder motion for ``time`` (s): per frame the marker's rotation (n, 3, 3) and position
    (n, 3) in the camera frame (m): reach, a wrist turn through the bite, a pull, a stop, a return."""
    linear = time / max(time[-1], 1e-9)
    # the hand stops for a moment half-way (speed falls smoothly to zero and picks up again)
    tau = linear + np.sin(2 * np.pi * linear) / (2 * np.pi)
    position = np.column_stack(
        [
            0.03 * np.sin(2 * np.pi * tau) + 0.01 * np.sin(6 * np.pi * tau),
            0.015 * np.cos(2 * np.pi * tau) - 0.005 * np.sin(4 * np.pi * tau),
            0.30 + 0.02 * np.sin(2 * np.pi * tau + 0.5),
        ]
    )
    angles = np.column_stack(
        [0.35 * np.sin(2 * np.pi * tau), 0.3 * np.sin(4 * np.pi * tau + 0.3), 0.8 * np.sin(2 * np.pi * tau)]
    )
    rotations = np.array([FACING_CAMERA @ rotation_xyz(a) for a in angles])
    return rotations, position


def wrist_motion(
    time: NDArray[np.float64], duration: float | None = None
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """An instrument handled at 30 cm: per frame the body's rotation (n, 3, 3) and position (n, 3) in the
    camera frame (m). The hand reaches and returns (+/-4 cm), the wrist rolls the instrument about its
    shaft through 200 deg and back (the needle-driving turn), and tilts it by up to 20 deg, over
    ``duration`` (s, by default the last time)."""
    linear = time / max(duration or time[-1], 1e-9)
    tau = linear + np.sin(2 * np.pi * linear) / (2 * np.pi)
    position = np.column_stack(
        [
            0.04 * np.sin(2 * np.pi * tau),
            0.02 * np.sin(4 * np.pi * tau),
            0.30 + 0.03 * np.sin(2 * np.pi * tau + 0.7),
        ]
    )
    roll = np.radians(100.0) * np.sin(2 * np.pi * tau)
    tilt = np.radians(20.0) * np.sin(4 * np.pi * tau + 0.4)
    rotations = np.array(
        [FACING_CAMERA @ rotation_xyz(np.array([t, r, 0.0])) for r, t in zip(roll, tilt, strict=True)]
    )
    return rotations, position


def pivot_motion(
    count: int, body: MarkerBody, pivot: NDArray[np.float64], tilt_deg: float = 30.0
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """An instrument pivoting about its tip resting at ``pivot`` (camera frame, m): ``count`` poses
    (rotations, body origins) sweeping a cone of half-angle ``tilt_deg`` twice round."""
    rotations, origins = [], []
    upright = FACING_CAMERA @ rotation_xyz(np.array([0.0, np.radians(45.0), 0.0]))  # an edge to the camera
    for k in range(count):
        turn = 4 * np.pi * k / count
        tilt = np.radians(tilt_deg) * (0.4 + 0.6 * k / max(count - 1, 1))
        rotation = rotation_xyz(np.array([tilt * np.cos(turn), 0.0, tilt * np.sin(turn)])) @ upright
        rotations.append(rotation)
        origins.append(pivot - rotation @ np.asarray(body.tip_offset_m))
    return np.array(rotations), np.array(origins)


def board_frame(
    rotation: NDArray[np.float64],
    centre: NDArray[np.float64],
    board: BoardSpec | None = None,
    size: tuple[int, int] = (1280, 720),
    camera_matrix: NDArray[np.float64] | None = None,
    seed: int = 5,
) -> NDArray[np.uint8]:
    """One grey frame of the board posed by ``rotation`` (camera <- board; board frame: origin at its
    top-left corner, x along its rows, y down its columns, z into it) with its centre at ``centre`` (m)."""
    board = board or BoardSpec()
    camera_matrix = (
        default_camera_matrix(size, focal_px=size[0] * 0.9) if camera_matrix is None else camera_matrix
    )
    columns, rows = board.squares
    width_m, height_m = columns * board.square_m, rows * board.square_m
    texture = board.board().generateImage((columns * 120, rows * 120), marginSize=0, borderBits=1)
    corners = np.array([[0, 0, 0], [width_m, 0, 0], [width_m, height_m, 0], [0, height_m, 0]], dtype=float)
    rng = np.random.default_rng(seed)
    frame = background(size, rng)
    draw_plane(
        frame,
        texture,
        corners,
        rotation,
        centre - rotation @ np.array([width_m / 2, height_m / 2, 0]),
        camera_matrix,
    )
    return np.clip(frame + rng.normal(0, 1.5, frame.shape), 0, 255).astype(np.uint8)


def write_frames(path: str | Path, frames: list[NDArray[np.uint8]], fps: int = 10) -> None:
    """Grey frames to a high-quality H.264 file."""
    import av

    with av.open(str(path), mode="w") as container:
        stream = container.add_stream("libx264", rate=fps, options={"crf": "12", "preset": "veryfast"})
        stream.height, stream.width = frames[0].shape
        stream.pix_fmt = "yuv420p"
        for frame in frames:
            for packet in stream.encode(av.VideoFrame.from_ndarray(frame, format="gray")):
                container.mux(packet)
        for packet in stream.encode():
            container.mux(packet)


def board_views_video(
    path: str | Path,
    board: BoardSpec | None = None,
    size: tuple[int, int] = (1280, 720),
    camera_matrix: NDArray[np.float64] | None = None,
    fps: int = 10,
    hold_frames: int = 4,
) -> NDArray[np.float64]:
    """A video of a ChArUco board held square-on and tilted 25 deg left, right, up and down, three
    places each (each view held ``hold_frames`` frames), as a person calibrating live would show it.
    Returns the camera matrix used."""
    import av

    board = board or BoardSpec()
    camera_matrix = (
        default_camera_matrix(size, focal_px=size[0] * 0.9) if camera_matrix is None else camera_matrix
    )
    rng = np.random.default_rng(5)
    columns, rows = board.squares
    width_m, height_m = columns * board.square_m, rows * board.square_m
    texture = board.board().generateImage((columns * 120, rows * 120), marginSize=0, borderBits=1)
    corners = np.array([[0, 0, 0], [width_m, 0, 0], [width_m, height_m, 0], [0, height_m, 0]], dtype=float)
    centre = np.array([width_m / 2, height_m / 2, 0.0])
    tilt = np.radians(25.0)
    turns = [(0.0, 0.0), (0.0, -tilt), (0.0, tilt), (tilt, 0.0), (-tilt, 0.0)]
    places = [np.array([-0.03, -0.01, 0.42]), np.array([0.0, 0.01, 0.38]), np.array([0.03, 0.0, 0.46])]
    bench = background(size, rng)
    with av.open(str(path), mode="w") as container:
        stream = container.add_stream("libx264", rate=fps, options={"crf": "12", "preset": "veryfast"})
        stream.width, stream.height = size
        stream.pix_fmt = "yuv420p"
        for about_x, about_y in turns:
            for place in places:
                rotation = rotation_xyz(np.array([about_x, about_y, 0.0]))
                frame = bench.copy()
                draw_plane(frame, texture, corners, rotation, place - rotation @ centre, camera_matrix)
                for _ in range(hold_frames):
                    noisy = np.clip(frame + rng.normal(0, 1.5, frame.shape), 0, 255).astype(np.uint8)
                    for packet in stream.encode(av.VideoFrame.from_ndarray(noisy, format="gray")):
                        container.mux(packet)
        for packet in stream.encode():
            container.mux(packet)
    return camera_matrix


def write_bench_video(
    path: str | Path,
    duration_s: float = 6.0,
    fps: int = 30,
    size: tuple[int, int] = (1920, 1080),
    camera_matrix: NDArray[np.float64] | None = None,
    marker: MarkerBody | None = None,
    seed: int = 0,
    noise: float = 2.0,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Render the suturing motion of a flat-marked needle holder; returns (time, true tip path)."""
    marker = marker or MarkerBody.flat()
    time = np.arange(int(round(duration_s * fps))) / fps
    rotations, positions = suturing_motion(time)
    camera_matrix = default_camera_matrix(size) if camera_matrix is None else camera_matrix
    write_instrument_video(path, rotations, positions, marker, fps, size, camera_matrix, seed, noise)
    return time, np.einsum("nij,j->ni", rotations, np.asarray(marker.tip_offset_m)) + positions


def write_instrument_video(
    path: str | Path,
    rotations: NDArray[np.float64],
    positions: NDArray[np.float64],
    body: MarkerBody,
    fps: float = 30.0,
    size: tuple[int, int] = (1280, 720),
    camera_matrix: NDArray[np.float64] | None = None,
    seed: int = 0,
    noise: float = 2.0,
    blur_frames: NDArray[np.float64] | None = None,
    occluded: NDArray[np.bool_] | None = None,
    others: tuple[tuple[MarkerBody, NDArray[np.float64], NDArray[np.float64]], ...] = (),
) -> None:
    """Render a body posed per frame by ``rotations`` (n, 3, 3) and ``positions`` (n, 3) (camera frame,
    m) to a video file (high-quality H.264 at ``fps``); ``others``: more bodies in the same frames, each
    (body, rotations, positions), drawn sharp.

    ``blur_frames`` (n, 3, 3 + 3) optional: per frame the body's pose at the end of the exposure (rotation
    columns then position), blurred by averaging 4 renders along the way; ``occluded`` (n,) bool: frames
    where a hand covers the instrument (a dark patch over every marker)."""
    import av

    camera_matrix = (
        default_camera_matrix(size, focal_px=size[0] * 0.9) if camera_matrix is None else camera_matrix
    )
    rng = np.random.default_rng(seed)
    textures = [face_texture(body, face) for face in body.faces]
    other_textures = [[face_texture(b, face) for face in b.faces] for b, _, _ in others]
    bench = background(size, rng)
    with av.open(str(path), mode="w") as container:
        stream = container.add_stream(
            "libx264", rate=int(round(fps)), options={"crf": "12", "preset": "veryfast"}
        )
        stream.width, stream.height = size
        stream.pix_fmt = "yuv420p"
        for k, (rotation, translation) in enumerate(zip(rotations, positions, strict=True)):
            if blur_frames is None:
                frame = bench.copy()
                draw_body(frame, textures, rotation, translation, camera_matrix)
            else:
                end_rotation, end_position = blur_frames[k][:, :3], blur_frames[k][:, 3]
                renders = []
                for s in np.linspace(0.0, 1.0, 4):
                    frame = bench.copy()
                    turn = _interpolate_rotation(rotation, end_rotation, s)
                    draw_body(frame, textures, turn, (1 - s) * translation + s * end_position, camera_matrix)
                    renders.append(frame.astype(np.float32))
                frame = np.mean(renders, axis=0).astype(np.uint8)
            for faces, (_, turns, places) in zip(other_textures, others, strict=True):
                draw_body(frame, faces, turns[k], places[k], camera_matrix)
            if occluded is not None and occluded[k]:
                _cover(frame, body, rotation, translation, camera_matrix)
            # sensor noise in single precision: the same Gaussian, a third of the cost of a float64 draw
            grain = rng.standard_normal(frame.shape, dtype=np.float32)
            grain *= noise
            grain += frame
            frame = np.clip(grain, 0, 255, out=grain).astype(np.uint8)
            for packet in stream.encode(av.VideoFrame.from_ndarray(frame, format="gray")):
                container.mux(packet)
        for packet in stream.encode():
            container.mux(packet)


def _interpolate_rotation(start, end, s: float) -> NDArray[np.float64]:
    from scipy.spatial.transform import Rotation, Slerp

    return Slerp([0.0, 1.0], Rotation.from_matrix([start, end]))([s]).as_matrix()[0]


def _cover(frame, body: MarkerBody, rotation, translation, camera_matrix) -> None:
    """A dark patch (a hand) over every marker of the body."""
    points = np.concatenate([body.corners(k) for k in body.ids]) @ rotation.T + translation
    projected = points @ camera_matrix.T
    image = projected[:, :2] / projected[:, 2:3]
    low = np.maximum(image.min(axis=0) - 4, 0).astype(int)
    high = np.minimum(image.max(axis=0) + 4, [frame.shape[1], frame.shape[0]]).astype(int)
    frame[low[1] : high[1], low[0] : high[0]] = 60


def charuco_views(
    board: BoardSpec | None = None,
    count: int = 12,
    size: tuple[int, int] = (1920, 1080),
    camera_matrix: NDArray[np.float64] | None = None,
    seed: int = 1,
) -> list[NDArray[np.uint8]]:
    """Grey images of a ChArUco board at varied tilts and distances, as a calibration session takes them."""
    board = board or BoardSpec()
    camera_matrix = default_camera_matrix(size) if camera_matrix is None else camera_matrix
    rng = np.random.default_rng(seed)
    columns, rows = board.squares
    width_m, height_m = columns * board.square_m, rows * board.square_m
    texture = board.board().generateImage((columns * 120, rows * 120), marginSize=0, borderBits=1)
    # board coordinates: origin at the top-left corner, x right, y down (OpenCV's CharucoBoard)
    corners = np.array([[0, 0, 0], [width_m, 0, 0], [width_m, height_m, 0], [0, height_m, 0]], dtype=float)
    centre = np.array([width_m / 2, height_m / 2, 0.0])
    views = []
    for _ in range(count):
        tilt = rotation_xyz(
            np.array([rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5), rng.uniform(-0.3, 0.3)])
        )
        rotation = tilt  # board z into the scene: its front faces the camera
        translation = np.array([rng.uniform(-0.05, 0.05), rng.uniform(-0.03, 0.03), rng.uniform(0.35, 0.55)])
        translation = translation - rotation @ centre
        frame = background(size, rng)
        draw_plane(frame, texture, corners, rotation, translation, camera_matrix)
        views.append(np.clip(frame + rng.normal(0, 2.0, frame.shape), 0, 255).astype(np.uint8))
    return views
