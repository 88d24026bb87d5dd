"""The heads-up panel drawn onto replay frames: phase, force, tip speed, entry angle, with the expert band.

A value inside the experts' inter-quartile band for the current phase is shown in
green, outside it in orange; without a reference, in white.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

GREEN = (80, 220, 100)
ORANGE = (255, 160, 40)
WHITE = (240, 240, 240)


@dataclass(frozen=True)
class HudLine:
    label: str
    value: str
    band: str = ""
    inside: bool | None = None  # None: no band to compare with


def value_line(
    label: str, value: float, unit: str, band: tuple[float, float, float] | None, factor: float = 1.0
):
    """A panel line for a value (SI) against an expert (q1, median, q3) band (SI), shown times ``factor``."""
    if not np.isfinite(value):
        return HudLine(label, "-")
    text = f"{value * factor:.1f} {unit}"
    if band is None:
        return HudLine(label, text)
    q1, _, q3 = band
    return HudLine(label, text, f"experts {q1 * factor:.1f}-{q3 * factor:.1f}", bool(q1 <= value <= q3))


def draw_hud(
    pixels: NDArray[np.uint8], title: str, lines: list[HudLine], scale: float = 1.0
) -> NDArray[np.uint8]:
    """Draw a translucent panel in the top-left corner (in place; returns ``pixels``)."""
    import cv2

    font = cv2.FONT_HERSHEY_SIMPLEX
    size = 0.5 * scale
    thickness = max(1, int(round(scale)))
    step = int(22 * scale)
    width = int(360 * scale)
    height = step * (len(lines) + 1) + int(10 * scale)
    height = min(height, pixels.shape[0])
    width = min(width, pixels.shape[1])
    region = pixels[:height, :width]
    region[:] = (region.astype(np.uint16) * 2 // 5).astype(np.uint8)  # darken to 40 %
    y = int(18 * scale)
    cv2.putText(pixels, title, (int(8 * scale), y), font, size * 1.05, WHITE, thickness, cv2.LINE_AA)
    for line in lines:
        y += step
        colour = WHITE if line.inside is None else (GREEN if line.inside else ORANGE)
        cv2.putText(pixels, f"{line.label}:", (int(8 * scale), y), font, size, WHITE, thickness, cv2.LINE_AA)
        cv2.putText(pixels, line.value, (int(120 * scale), y), font, size, colour, thickness, cv2.LINE_AA)
        if line.band:
            cv2.putText(
                pixels, line.band, (int(215 * scale), y), font, size * 0.85, WHITE, thickness, cv2.LINE_AA
            )
    return pixels


def label_view(pixels: NDArray[np.uint8], text: str, scale: float = 1.0) -> NDArray[np.uint8]:
    """A caption at the bottom-left of a view (e.g. "trainee T01" / "expert E02")."""
    import cv2

    y = pixels.shape[0] - int(12 * scale)
    cv2.putText(pixels, text, (int(10 * scale), y), cv2.FONT_HERSHEY_SIMPLEX, 0.6 * scale, (20, 20, 20),
                max(1, int(round(scale))), cv2.LINE_AA)  # fmt: skip
    return pixels
