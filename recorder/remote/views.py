"""A remote station's 3-D view for the dashboard's live page: one JPEG per session, replaced in place.

A station sends the frame its window drew last (``PUT /api/sessions/{session}/view``); the central
recorder keeps only the newest one, outside the session's folder, and takes it away when the session
closes. A view is never part of the recording: a lost or refused frame loses nothing that is scored.
Every body is checked completely before it is kept: its size, a JPEG's markers up to the frame
header, the declared size (refused before anything is decoded, so a small body cannot ask for
gigabytes), the end-of-image marker, and a full decode (which proves an image of that size; like any
viewer, it tolerates damaged picture data inside it).
"""

from __future__ import annotations

import os
import struct
from pathlib import Path

from recorder.remote.protocol import RemoteError

MAX_VIEW_BYTES = 2**20
"""Largest view body accepted (1 MiB; a 1280x720 frame at quality 75 is about 60 kB)."""
MAX_VIEW_SIDE = 4096
"""Largest width or height of a view (px)."""
VIEWS_FOLDER = ".views"
"""Under the ingest root, beside the stations' folders (a name no station id can take)."""
_START_OF_FRAME = frozenset({0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF})
_STANDALONE = frozenset({0x01, *range(0xD0, 0xD8)})


def view_path(root: Path, station: str, session_id: str) -> Path:
    """Where the newest view of ``station``'s session ``session_id`` is kept."""
    return Path(root) / VIEWS_FOLDER / station / f"{session_id}.jpg"


def jpeg_size(body: bytes) -> tuple[int, int]:
    """(width, height) a JPEG declares in its frame header; RemoteError (422) if ``body`` is not a
    JPEG up to that header."""
    if body[:2] != b"\xff\xd8":
        raise RemoteError(422, "a view must be a JPEG image (it does not start with the JPEG marker)")
    at = 2
    while at + 4 <= len(body):
        if body[at] != 0xFF:
            raise RemoteError(422, f"the view's JPEG markers are broken at byte {at}")
        marker = body[at + 1]
        if marker == 0xFF:  # fill byte
            at += 1
            continue
        if marker in _STANDALONE:
            at += 2
            continue
        (length,) = struct.unpack(">H", body[at + 2 : at + 4])
        if length < 2:
            raise RemoteError(422, f"the view's JPEG segment at byte {at} has length {length}")
        if marker in _START_OF_FRAME:
            if at + 9 > len(body):
                break
            height, width = struct.unpack(">HH", body[at + 5 : at + 9])
            return width, height
        if marker == 0xD9:
            break
        at += 2 + length
    raise RemoteError(422, "the view is not a whole JPEG image (no frame header)")


def checked_view(body: bytes) -> tuple[int, int]:
    """The (width, height) of a view body that is a whole JPEG within the limits; RemoteError
    (413 for size, 422 otherwise) naming what is wrong."""
    if len(body) > MAX_VIEW_BYTES:
        raise RemoteError(413, f"a view of {len(body)} bytes exceeds {MAX_VIEW_BYTES}")
    width, height = jpeg_size(body)
    if not body.endswith(b"\xff\xd9"):
        raise RemoteError(422, "the view is not a whole JPEG image (no end-of-image marker)")
    if not (1 <= width <= MAX_VIEW_SIDE and 1 <= height <= MAX_VIEW_SIDE):
        raise RemoteError(422, f"a view of {width}x{height} px is outside 1-{MAX_VIEW_SIDE} px on each side")
    import cv2
    import numpy as np

    image = cv2.imdecode(np.frombuffer(body, dtype=np.uint8), cv2.IMREAD_COLOR)
    if image is None or image.shape[:2] != (height, width):
        raise RemoteError(422, "the view's JPEG data does not decode")
    return width, height


def keep_view(path: Path, body: bytes) -> None:
    """Replace the view at ``path`` (a reader never sees half a file; not synced: a view is not kept
    across a crash)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_suffix(".part")
    partial.write_bytes(body)
    os.replace(partial, path)
