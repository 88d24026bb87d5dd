"""A station's camera set-up: its calibration, the instruments' registered tips, the camera device.

Kept in the data directory so a course sets up once per station:

- ``camera.json``: the camera's calibration (:class:`sim.tracking.camera.Camera`), written by the
  calibrate command (from photos, or live from the camera);
- ``table.json``: how the camera sits over the table (the rotation from its axes into the device
  frame), from the board lying on the table (``calibrate --table``); without it the camera is taken
  to be on the monitor facing the trainee;
- ``instruments.json``: each instrument's tip offset in its marker cube's frame (mm), with the
  pivot calibration's residual, written by ``instruments register``; an instrument never registered
  uses its nominal offset (:data:`sim.tracking.markers.INSTRUMENTS`).

The file is read as data someone else may have edited: every field is checked before use.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from sessions.catalog import CatalogError
from sessions.config import data_home
from sim.devices.camera import PLACEMENTS, CameraDevice, camera_source, open_frames
from sim.errors import TrackingError
from sim.tracking.camera import BoardSpec, Camera
from sim.tracking.guided import CalibrationViews, table_registration
from sim.tracking.markers import INSTRUMENTS, MarkerBody
from sim.tracking.pivot import PivotResult, pivot_calibration
from sim.tracking.pose import BodyTracker

CAMERA_FILE = "camera.json"
INSTRUMENTS_FILE = "instruments.json"
TABLE_FILE = "table.json"
"""The camera's axes into the device frame, measured with the board lying on the table."""
MAX_TIP_OFFSET_MM = 400.0
"""No instrument's tip lies further than this from its marker cube."""


def camera_calibration(home: Path) -> Camera:
    """The station's camera calibration, or an error saying how to make one."""
    path = home / CAMERA_FILE
    if not path.exists():
        raise CatalogError(
            f"this station's camera is not calibrated ({path} does not exist)", remedy=("calibrate", "camera")
        )
    return Camera.load(path)


def registered_tips(home: Path) -> dict[str, dict]:
    """{instrument: {"tip_offset_mm": [x, y, z], "residual_mm": r, "registered_at": iso}} as stored."""
    path = home / INSTRUMENTS_FILE
    if not path.exists():
        return {}
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError) as error:
        raise CatalogError(f"{path} is not readable: {error}; register the instruments again") from None
    if not isinstance(data, dict):
        raise CatalogError(f"{path} must hold an object of instruments; register the instruments again")
    for name, entry in data.items():
        problem = _entry_problem(name, entry)
        if problem:
            raise CatalogError(f"{path}: {problem}; register the instruments again")
    return data


def _entry_problem(name: object, entry: object) -> str | None:
    if name not in INSTRUMENTS:
        return f"unknown instrument {name!r} (one of {', '.join(INSTRUMENTS)})"
    if not isinstance(entry, dict) or set(entry) != {"tip_offset_mm", "residual_mm", "registered_at"}:
        return f"{name}: expected tip_offset_mm, residual_mm and registered_at"
    offset = entry["tip_offset_mm"]
    if not (
        isinstance(offset, list)
        and len(offset) == 3
        and all(isinstance(v, (int, float)) and math.isfinite(v) for v in offset)
        and math.hypot(*offset) <= MAX_TIP_OFFSET_MM
    ):
        return f"{name}: tip_offset_mm must be three finite numbers within {MAX_TIP_OFFSET_MM:.0f} mm"
    residual = entry["residual_mm"]
    if not (isinstance(residual, (int, float)) and math.isfinite(residual) and residual >= 0):
        return f"{name}: residual_mm must be a finite number, not negative"
    try:
        datetime.fromisoformat(str(entry["registered_at"]))
    except ValueError:
        return f"{name}: registered_at must be an ISO date-time"
    return None


def instrument_body(home: Path, name: str) -> MarkerBody:
    """An instrument's markers with its registered tip (its nominal tip when never registered)."""
    if name not in INSTRUMENTS:
        raise CatalogError(f"unknown instrument {name!r}; one of {', '.join(INSTRUMENTS)}")
    body = INSTRUMENTS[name]
    entry = registered_tips(home).get(name)
    if entry is None:
        return body
    return body.with_tip([v / 1e3 for v in entry["tip_offset_mm"]])


def save_tip(home: Path, name: str, tip_offset_m, residual_m: float) -> Path:
    """Store an instrument's registered tip (written whole to a new file, then renamed over the old)."""
    data = registered_tips(home)
    data[name] = {
        "tip_offset_mm": [round(float(v) * 1e3, 4) for v in tip_offset_m],
        "residual_mm": round(float(residual_m) * 1e3, 4),
        "registered_at": datetime.now(UTC).isoformat(timespec="seconds"),
    }
    return _write_whole(home / INSTRUMENTS_FILE, data)


def table_axes(home: Path):
    """The registered rotation from the camera's axes into the device frame, or None (never registered)."""
    path = home / TABLE_FILE
    if not path.exists():
        return None
    try:
        data = json.loads(path.read_text())
        rotation = np.array(data["device_from_camera"], dtype=np.float64)
        if set(data) != {"device_from_camera", "reprojection_px", "registered_at"} or rotation.shape != (
            3,
            3,
        ):
            raise ValueError("expected device_from_camera (3x3), reprojection_px and registered_at")
    except (OSError, ValueError, KeyError, TypeError) as error:
        raise CatalogError(f"{path} is not readable: {error}; register the table again") from None
    if not (np.all(np.isfinite(rotation)) and np.allclose(rotation @ rotation.T, np.eye(3), atol=1e-6)
            and abs(np.linalg.det(rotation) - 1.0) < 1e-6):  # fmt: skip
        raise CatalogError(f"{path}: device_from_camera is not a rotation; register the table again")
    return rotation


def save_table(home: Path, rotation, reprojection_px: float) -> Path:
    data = {
        "device_from_camera": np.asarray(rotation).round(9).tolist(),
        "reprojection_px": round(float(reprojection_px), 4),
        "registered_at": datetime.now(UTC).isoformat(timespec="seconds"),
    }
    return _write_whole(home / TABLE_FILE, data)


def _write_whole(path: Path, data: dict) -> Path:
    """Write JSON to a new file, then rename it over the old: a crash leaves the old one whole."""
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_suffix(".json.partial")
    partial.write_text(json.dumps(data, indent=2))
    partial.replace(path)
    return path


def register_table(spec: str, home: Path, board: BoardSpec | None = None) -> tuple[np.ndarray, float, Path]:
    """Register the table from the first frame of ``spec`` that shows the board lying on it."""
    camera = camera_calibration(home)
    frames, opened = open_frames(camera_source(spec))
    problem = None
    try:
        for _, frame in frames:
            try:
                rotation, error = table_registration(frame, camera, board)
            except TrackingError as refused:
                problem = refused
                continue
            return rotation, error, save_table(home, rotation, error)
    finally:
        opened.close()
    raise problem or CatalogError(f"camera source {spec} sent no frames")


def open_camera_device(
    spec: str,
    clock: str,
    home: Path | None,
    instrument: str = "needle-holder",
    placement: str | None = None,
    companions: tuple[str, ...] = (),
) -> tuple[CameraDevice, float | None]:
    """The device ``camera[:INDEX|URL|FILE]`` names for ``instrument`` (and ``companions``, other
    instruments tracked in the same frames: :meth:`CameraDevice.companion`), and a video file's length
    (s). ``placement``: a named one (:data:`sim.devices.camera.PLACEMENTS`), else the registered table's,
    else the camera on the monitor facing the trainee."""
    home = home or data_home()
    source = camera_source(spec)
    if clock == "simulated" and not isinstance(source, Path):
        raise CatalogError(
            "a live camera runs in real time; a simulated clock replays a video file (camera:FILE)"
        )
    if placement is not None and placement not in PLACEMENTS:
        raise CatalogError(f"unknown camera placement {placement!r}; one of {', '.join(PLACEMENTS)}")
    registered = table_axes(home) if placement is None else None
    axes = registered if registered is not None else PLACEMENTS[placement or "facing"]
    device = CameraDevice(
        source, camera_calibration(home), instrument_body(home, instrument), clock, device_from_camera=axes,
        companions=tuple(instrument_body(home, name) for name in companions),
    )  # fmt: skip
    return device, device.duration


def calibrate_live(
    spec: str,
    home: Path,
    board: BoardSpec | None = None,
    out: Path | None = None,
    progress: Callable[[str | None, list[str]], None] | None = None,
    timeout_s: float = 180.0,
    window=None,
) -> tuple[Camera, Path]:
    """Calibrate the camera ``spec`` (index, URL or a video of the board) from the frames it sends,
    guided view by view (``progress(kind kept or None, kinds missing)`` after each frame, and on
    ``window``, a :class:`sessions.running.calibration_window.CalibrationWindow`, the picture, the
    checklist and which way to turn the board next); writes the station's calibration (``out``,
    default the data directory's) only when the fit is good."""
    views = CalibrationViews(board)
    frames, opened = open_frames(camera_source(spec))
    start = None
    try:
        for stamp, frame in frames:
            start = stamp if start is None else start
            kept = views.offer(stamp, frame)
            if progress is not None:
                progress(kept, views.missing())
            if window is not None:
                window.show(frame, views.counts(), views.last_corners)
            if not views.missing() or stamp - start > timeout_s:
                break
    finally:
        opened.close()
    camera = views.calibrate()
    path = out or home / CAMERA_FILE
    path.parent.mkdir(parents=True, exist_ok=True)
    camera.save(path)
    return camera, path


def register_instrument(
    spec: str,
    home: Path,
    name: str,
    seconds: float = 15.0,
    progress: Callable[[int], None] | None = None,
) -> tuple[PivotResult, Path]:
    """Pivot calibration of ``name`` from the camera ``spec`` (``seconds`` of a live camera, or a whole
    video file); stores the tip only when the result is good."""
    body = INSTRUMENTS.get(name)
    if body is None:
        raise CatalogError(f"unknown instrument {name!r}; one of {', '.join(INSTRUMENTS)}")
    tracker = BodyTracker(camera_calibration(home), body)
    rotations, translations = [], []
    frames, opened = open_frames(camera_source(spec))
    start = None
    try:
        for stamp, frame in frames:
            start = stamp if start is None else start
            if stamp - start > seconds:
                break
            pose = tracker.locate(frame)
            if pose is not None:
                rotations.append(pose.rotation)
                translations.append(pose.translation)
                if progress is not None:
                    progress(len(rotations))
    finally:
        opened.close()
    result = pivot_calibration(np.array(rotations).reshape(-1, 3, 3), np.array(translations).reshape(-1, 3))
    return result, save_tip(home, name, result.tip_offset, result.residual)
