"""Browser-playable video through PyAV: H.264 in MP4 with faststart, or VP9 in WebM.

Encoding runs in a worker thread (PyAV releases the GIL inside FFmpeg), so the next
frame renders while the last one encodes. OpenCV's own writer is not used: it cannot
write H.264 here and its mp4v output does not play in browsers.
"""

from __future__ import annotations

import queue
import threading
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from metrics.errors import MetricsError

VP9_OPTIONS = {"deadline": "realtime", "cpu-used": "8", "row-mt": "1", "crf": "32", "b": "0"}
CODECS = {
    # ultrafast: replays are mostly flat background, so files stay small (~25 kB/s at 720p), and it
    # leaves the second core to the renderer (veryfast cost the 10k-node artery replay 15 % of its rate)
    ".mp4": ("libx264", "yuv420p", {"preset": "ultrafast", "crf": "23"}, {"movflags": "+faststart"}),
    ".webm": ("libvpx-vp9", "yuv420p", VP9_OPTIONS, {}),
}
"""Suffix -> (encoder, pixel format, encoder options, container options)."""


def check_video_path(path: str | Path) -> Path:
    """The path, if its suffix names a codec this writer has; else a MetricsError saying which do."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in CODECS:
        raise MetricsError(f"video {path}: use .mp4 (H.264) or .webm (VP9); got {suffix or 'no suffix'!r}")
    return path


class VideoWriter:
    """Write RGB frames (H, W, 3) uint8 to ``path`` (.mp4 -> H.264, .webm -> VP9) at ``fps``."""

    def __init__(self, path: str | Path, size: tuple[int, int], fps: int = 30, queue_frames: int = 8) -> None:
        import av

        self.path = check_video_path(path)
        suffix = self.path.suffix.lower()
        width, height = size
        if width % 2 or height % 2 or width < 16 or height < 16:
            raise MetricsError(f"video size must be even and at least 16x16 pixels; got {width}x{height}")
        codec, pixel_format, options, container_options = CODECS[suffix]
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._partial = self.path.with_name(self.path.name + ".partial" + suffix)
        self._container = av.open(str(self._partial), mode="w", options=container_options)
        self._stream = self._container.add_stream(codec, rate=int(fps), options=options)
        self._stream.width, self._stream.height = width, height
        self._stream.pix_fmt = pixel_format
        self._stream.thread_count = 2
        self.size = size
        self.frames = 0
        self._queue: queue.Queue = queue.Queue(maxsize=queue_frames)
        self._error: BaseException | None = None
        self._worker = threading.Thread(target=self._encode_loop, name="vascsim-video", daemon=True)
        self._worker.start()

    def _encode_loop(self) -> None:
        import av

        while True:
            pixels = self._queue.get()
            if pixels is None:
                break
            if self._error is not None:
                continue
            try:
                frame = av.VideoFrame.from_ndarray(pixels, format="rgb24")
                for packet in self._stream.encode(frame):
                    self._container.mux(packet)
            except BaseException as error:  # reported to the writer's thread at the next call
                self._error = error

    def write(self, pixels: NDArray[np.uint8]) -> None:
        if self._error is not None:
            raise MetricsError(f"encoding {self.path} failed: {self._error}")
        height, width = pixels.shape[:2]
        if (width, height) != tuple(self.size) or pixels.dtype != np.uint8 or pixels.shape[2] != 3:
            raise MetricsError(
                f"frame of shape {pixels.shape} {pixels.dtype} does not fit a {self.size} video"
            )
        self._queue.put(np.ascontiguousarray(pixels))
        self.frames += 1

    def close(self) -> Path:
        """Flush, finish the file (moov atom first for MP4) and move it into place."""
        self._queue.put(None)
        self._worker.join()
        try:
            if self._error is None:
                for packet in self._stream.encode():
                    self._container.mux(packet)
        finally:
            self._container.close()
        if self._error is not None:
            self._partial.unlink(missing_ok=True)
            raise MetricsError(f"encoding {self.path} failed: {self._error}")
        self._partial.replace(self.path)
        return self.path

    def abort(self) -> None:
        self._queue.put(None)
        self._worker.join()
        try:
            self._container.close()
        finally:
            self._partial.unlink(missing_ok=True)

    def __enter__(self) -> VideoWriter:
        return self

    def __exit__(self, kind, error, trace) -> None:
        if kind is None:
            self.close()
        else:
            self.abort()
