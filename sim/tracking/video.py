"""Where camera frames come from: a video file (PyAV) or a live camera (OpenCV capture).

Both give ``(time_s, grey frame)`` pairs. A file's times are its frames' presentation times from the
first frame; a live camera's are ``time.perf_counter()`` when the frame was grabbed, the clock the
real-time loop runs on, so the delay from grab to the haptic loop can be measured.
"""

from __future__ import annotations

import time as clock
from collections.abc import Iterable, Iterator
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from sim.errors import TrackingError


class VideoFile:
    """The frames of a video file, grey, with their times (s from the first frame)."""

    def __init__(self, path: str | Path) -> None:
        import av

        self.path = Path(path)
        try:
            self._container = av.open(str(self.path))
            self._stream = self._container.streams.video[0]
        except (av.FFmpegError, OSError, IndexError) as error:
            raise TrackingError(f"video {self.path} cannot be opened: {error}") from None
        self._stream.thread_type = "AUTO"
        self.fps = float(self._stream.average_rate or self._stream.guessed_rate or 0) or 30.0
        self.frame_count = int(self._stream.frames or 0)
        self.size = (int(self._stream.width), int(self._stream.height))

    def __iter__(self) -> Iterator[tuple[float, NDArray[np.uint8]]]:
        import av

        first = None
        base = self._stream.time_base
        try:
            for k, frame in enumerate(self._container.decode(self._stream)):
                stamp = float(frame.pts * base) if frame.pts is not None and base else k / self.fps
                first = stamp if first is None else first
                yield stamp - first, frame.to_ndarray(format="gray")
        except av.FFmpegError as error:
            raise TrackingError(f"video {self.path} stopped decoding: {error}") from None
        finally:
            self._container.close()

    def close(self) -> None:
        try:
            self._container.close()
        except Exception:  # PyAV raises on a second close; the file is closed either way
            pass


def read_video(path: str | Path) -> tuple[Iterable[NDArray[np.uint8]], float, int]:
    """Frames (grey uint8) of a video file, its frame rate and frame count (0 if unknown)."""
    video = VideoFile(path)
    return (frame for _, frame in video), video.fps, video.frame_count


class LiveCamera:
    """A camera by index (``0``) or stream URL, through OpenCV's capture, grey frames with grab times.

    ``size``: the resolution asked for (width, height); the camera may give another, read ``size``.
    """

    def __init__(self, source: int | str, size: tuple[int, int] | None = (1280, 720), fps: float = 60.0):
        import cv2

        cv2.utils.logging.setLogLevel(
            cv2.utils.logging.LOG_LEVEL_ERROR
        )  # its own warnings say less than ours
        self.source = source
        self._capture = cv2.VideoCapture(source)
        if not self._capture.isOpened():
            raise TrackingError(
                f"camera {source!r} cannot be opened: check it is plugged in (list cameras with the "
                "devices command) and that this user may read /dev/video*"
            )
        if size is not None:
            self._capture.set(cv2.CAP_PROP_FRAME_WIDTH, size[0])
            self._capture.set(cv2.CAP_PROP_FRAME_HEIGHT, size[1])
        self._capture.set(cv2.CAP_PROP_FPS, fps)
        self._capture.set(cv2.CAP_PROP_BUFFERSIZE, 1)  # the newest frame, not a queue of stale ones
        self.size = (
            int(self._capture.get(cv2.CAP_PROP_FRAME_WIDTH)),
            int(self._capture.get(cv2.CAP_PROP_FRAME_HEIGHT)),
        )
        self.fps = float(self._capture.get(cv2.CAP_PROP_FPS) or fps)
        self.frame_count = 0

    def __iter__(self) -> Iterator[tuple[float, NDArray[np.uint8]]]:
        import cv2

        while True:
            if not self._capture.grab():
                raise TrackingError(f"camera {self.source!r} stopped sending frames")
            stamp = clock.perf_counter()
            ok, frame = self._capture.retrieve()
            if not ok:
                raise TrackingError(f"camera {self.source!r} sent a frame that cannot be read")
            yield stamp, cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY) if frame.ndim == 3 else frame

    def close(self) -> None:
        self._capture.release()


def list_cameras(
    limit: int = 8, devices: Path = Path("/dev"), sysfs: Path = Path("/sys/class/video4linux")
) -> list[tuple[str, str]]:
    """Video capture devices on this machine: (``camera:N``, what it is), from /dev/video* and the
    names video4linux gives them (in index order; a UVC webcam also lists its metadata node, which
    says so in its name)."""
    found = []
    for path in sorted(devices.glob("video*"), key=lambda p: (len(p.name), p.name)):
        index = path.name.removeprefix("video")
        if not index.isdigit() or int(index) >= limit:
            continue
        name_file = sysfs / path.name / "name"
        try:
            name = name_file.read_text().strip() or path.name
        except OSError:
            name = path.name
        found.append((f"camera:{index}", name[:80]))
    return found
