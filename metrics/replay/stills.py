"""Still images of a replay: the insertion frame (PNG), the surface stress map at insertion (EXR, in
pascals, for analysis) and the signal plots, all written through OpenImageIO."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from metrics.errors import MetricsError
from metrics.streams import SessionStreams
from sim.render import write_image

STRESS_MAP_PIXEL_M = 2e-5
"""Stress maps sample the wall every 20 micrometres."""


def stress_map(
    points: NDArray[np.float64],
    triangles: NDArray[np.int64],
    triangle_stress: NDArray[np.float64],
    view_normal: NDArray[np.float64],
    pixel: float = STRESS_MAP_PIXEL_M,
) -> tuple[NDArray[np.float32], NDArray[np.float64], NDArray[np.float64]]:
    """Orthographic map of the surface seen along ``-view_normal`` (the wall's outward normal at the
    insertion): float32 von Mises stress per pixel (Pa; NaN where no facing triangle), and the map's
    in-plane axes (u, v) in metres; pixel (row, col) is at origin + col * pixel * u - row * pixel * v."""
    import cv2

    normal = np.asarray(view_normal, dtype=np.float64)
    normal /= np.linalg.norm(normal)
    helper = np.array([1.0, 0.0, 0.0]) if abs(normal[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = helper - (helper @ normal) * normal
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    corners = points[triangles]
    facing = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]) @ normal > 0
    if not facing.any():
        raise MetricsError("no surface triangle faces the stress map's view direction")
    plane = np.stack([corners @ u, corners @ v], axis=-1)[facing]  # (F, 3, 2) metres
    low, high = plane.reshape(-1, 2).min(axis=0), plane.reshape(-1, 2).max(axis=0)
    width, height = (np.ceil((high - low) / pixel).astype(int) + 1).tolist()
    image = np.full((height, width), np.nan, dtype=np.float32)
    depth = (corners[facing] @ normal).mean(axis=1)
    for k in np.argsort(depth):  # nearer (higher along the normal) triangles drawn last
        columns = (plane[k, :, 0] - low[0]) / pixel
        rows = (high[1] - plane[k, :, 1]) / pixel
        polygon = np.round(np.stack([columns, rows], axis=-1) * 16).astype(np.int32)  # 4 fractional bits
        cv2.fillPoly(image, [polygon], float(triangle_stress[facing][k]), lineType=cv2.LINE_8, shift=4)
    return image, u, v


def write_stress_map(path: str | Path, image: NDArray[np.float32]) -> Path:
    """One float channel of von Mises stress (Pa) as OpenEXR."""

    return write_image(path, None, float_data=image)


def insertion_frame_index(streams: SessionStreams, times: NDArray[np.float64]) -> int | None:
    pierces = streams.events.loc[streams.events["kind"] == "pierce", "time"]
    if pierces.empty:
        return None
    return int(np.clip(np.searchsorted(times, float(pierces.iloc[0])) - 1, 0, len(times) - 1))
