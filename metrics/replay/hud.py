"""What a replay frame shows around the 3-D view: a heads-up strip above each view and a key beside them.

The strip carries the time, phase, force, tip speed, entry angle and the latest bite's miss of its
mark; a value inside the experts' inter-quartile band for the current phase is green, outside it
orange, white without a reference. The key on the right holds the wall's stress scale and what each
mark in the scene means. Neither is drawn over the tissue, and text is sized for the frame's height
so it stays readable when a 1280 x 720 video plays 530 px wide in the dashboard.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

GREEN = (80, 220, 100)
ORANGE = (255, 160, 40)
WHITE = (240, 240, 240)
GREY = (190, 190, 190)
STRIP = (32, 32, 36)
INK = (30, 30, 30)

PANEL_SHARE = 0.2
"""The key's share of the frame's width."""
TEXT = 0.95
"""Value text size at 720 px of frame height (OpenCV font scale); labels and bands are smaller."""


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


WIDEST_LINES = (
    HudLine("phase", "approach"),  # the longest of metrics.signals.alignment.PHASES
    HudLine("force", "8888.8 mN", "experts 888.8-888.8", True),
    HudLine("tip speed", "888.8 mm/s", "experts 88.8-88.8", True),
    HudLine("entry angle", "88 deg"),
    HudLine("bite", "8.8 mm off mark"),
)
"""The widest readout a frame can carry: the strip's height is set from it once per video."""


@dataclass(frozen=True)
class Key:
    """One entry of the key: a glyph ("line", "dot", "arrow"; several colours: a row of dots) in its
    RGB colours, and its meaning."""

    glyph: str
    colours: tuple[tuple[int, int, int], ...]
    text: str


@dataclass(frozen=True)
class FrameLayout:
    """Where things go in a ``width`` x ``height`` frame of ``views`` 3-D views side by side: a
    heads-up strip of ``strip`` px above each view, the key ``panel`` px wide on the right."""

    width: int
    height: int
    views: int
    strip: int
    panel: int

    @classmethod
    def of(
        cls, size: tuple[int, int], views: int = 1, readouts: Sequence[tuple[str, list[HudLine]]] = ()
    ) -> FrameLayout:
        """The layout whose strips hold each of ``readouts`` ((title, lines) per frame and view;
        without them, the widest a frame can carry: :data:`WIDEST_LINES`)."""
        width, height = size
        panel = int(round(PANEL_SHARE * width))
        view_width = (width - panel) // views
        shown = readouts or [("t = 888.88 s", list(WIDEST_LINES))]
        rows = max(len(_rows(title, lines, view_width, height / 720)) for title, lines in shown)
        return cls(width, height, views, min(_strip_height(rows, height / 720), height // 2), panel)

    @property
    def scale(self) -> float:
        return self.height / 720

    @property
    def view_size(self) -> tuple[int, int]:
        """The 3-D renderer's size for each view."""
        return (self.width - self.panel) // self.views, self.height - self.strip

    def compose(
        self, views: list[tuple[NDArray[np.uint8], str, list[HudLine]]], key: NDArray[np.uint8]
    ) -> NDArray[np.uint8]:
        """One frame: each view (pixels, strip title, readout) under its strip, the key on the right."""
        frame = np.full((self.height, self.width, 3), 255, dtype=np.uint8)
        view_width, view_height = self.view_size
        for index, (pixels, title, lines) in enumerate(views):
            x = index * view_width
            frame[: self.strip, x : x + view_width] = draw_strip(
                view_width, self.strip, title, lines, self.scale
            )
            frame[self.strip :, x : x + view_width] = pixels[:view_height, :view_width]
        frame[:, self.width - self.panel :] = key
        return frame


def _font():
    import cv2

    return cv2.FONT_HERSHEY_SIMPLEX


def _text_width(text: str, size: float, thickness: int) -> int:
    import cv2

    return cv2.getTextSize(text, _font(), size, thickness)[0][0]


def _thickness(scale: float) -> int:
    return max(1, int(round(2 * scale)))


def _strip_height(rows: int, scale: float) -> int:
    return int(round((14 + 38 * rows) * scale))


def _pieces(line: HudLine, scale: float) -> list[tuple[str, float, tuple[int, int, int]]]:
    """A readout item as (text, size, colour) runs: label, value, band."""
    colour = WHITE if line.inside is None else (GREEN if line.inside else ORANGE)
    pieces = [(line.label, 0.75 * TEXT * scale, GREY), (line.value, TEXT * scale, colour)]
    if line.band:
        pieces.append((f"({line.band})", 0.75 * TEXT * scale, GREY))
    return pieces


def _rows(title: str, lines: list[HudLine], width: int, scale: float) -> list[list]:
    """The readout laid out left to right in rows that fit ``width``: [(x, pieces), ...] per row."""
    thick = _thickness(scale)
    gap, space, margin = int(30 * scale), int(9 * scale), int(10 * scale)
    items = [[(title, TEXT * scale, WHITE)]] + [_pieces(line, scale) for line in lines]
    rows: list[list] = [[]]
    x = margin
    for pieces in items:
        size = sum(_text_width(t, s, thick) for t, s, _ in pieces) + space * (len(pieces) - 1)
        if rows[-1] and x + size > width - margin:
            rows.append([])
            x = margin
        rows[-1].append((x, pieces))
        x += size + gap
    return rows


def draw_strip(width: int, height: int, title: str, lines: list[HudLine], scale: float) -> NDArray[np.uint8]:
    """The heads-up strip: a dark band with the title then each readout, wrapped into rows."""
    import cv2

    strip = np.empty((height, width, 3), dtype=np.uint8)
    strip[:] = STRIP
    thick, space = _thickness(scale), int(9 * scale)
    baseline = int(36 * scale)
    for row in _rows(title, lines, width, scale):
        for x, pieces in row:
            for text, size, colour in pieces:
                cv2.putText(strip, text, (x, baseline), _font(), size, colour, thick, cv2.LINE_AA)
                x += _text_width(text, size, thick) + space
        baseline += int(38 * scale)
    return strip


def draw_key(
    height: int,
    width: int,
    scale: float,
    stress_range_kpa: tuple[float, float] | None,
    colours,
    keys: list[Key],
) -> NDArray[np.uint8]:
    """The key beside the views: the wall's stress scale (``colours``: a matplotlib colour map over
    ``stress_range_kpa``; none when that is None) and one line per :class:`Key`, wrapped to the
    panel's width."""
    import cv2

    panel = np.full((height, width, 3), 255, dtype=np.uint8)
    thick = _thickness(scale)
    size = 0.72 * TEXT * scale
    margin = int(12 * scale)
    y = int(34 * scale)
    if stress_range_kpa is not None:
        y = _draw_stress_scale(panel, y, height, scale, stress_range_kpa, colours)
    glyph = int(36 * scale)
    for key in keys:
        _draw_glyph(panel, key, margin, y - int(7 * scale), glyph, scale)
        for part in _wrap(key.text, width - 2 * margin - glyph - int(8 * scale), size, thick):
            cv2.putText(
                panel, part, (margin + glyph + int(8 * scale), y), _font(), size, INK, thick, cv2.LINE_AA
            )
            y += int(25 * scale)
        y += int(7 * scale)
    return panel


def _draw_stress_scale(panel, y: int, height: int, scale: float, stress_range_kpa, colours) -> int:
    """The stress colour bar with its ticks and heading from ``y`` down; where the key goes on."""
    import cv2

    thick = _thickness(scale)
    size = 0.72 * TEXT * scale
    margin = int(12 * scale)
    for text in ("wall stress", "von Mises, kPa"):
        cv2.putText(panel, text, (margin, y), _font(), size, INK, thick, cv2.LINE_AA)
        y += int(28 * scale)
    top, bar_height, bar_width = y - int(8 * scale), int(0.28 * height), int(26 * scale)
    shades = colours(np.linspace(1.0, 0.0, bar_height))[:, :3]
    panel[top : top + bar_height, margin : margin + bar_width] = (255 * shades[:, None, :]).astype(np.uint8)
    low, high = stress_range_kpa
    for fraction in (0.0, 0.25, 0.5, 0.75, 1.0):
        tick_y = top + int(round((1.0 - fraction) * (bar_height - 1)))
        cv2.line(
            panel, (margin + bar_width, tick_y), (margin + bar_width + int(6 * scale), tick_y), INK, thick
        )
        label = f"{low + fraction * (high - low):.0f}"
        cv2.putText(
            panel, label, (margin + bar_width + int(10 * scale), tick_y + int(8 * scale)),
            _font(), size, INK, thick, cv2.LINE_AA,
        )  # fmt: skip
    return top + bar_height + int(44 * scale)


def _draw_glyph(panel: NDArray[np.uint8], key: Key, x: int, y: int, length: int, scale: float) -> None:
    import cv2

    colour = tuple(int(c) for c in key.colours[0])
    thick = max(2, int(round(5 * scale)))
    if key.glyph == "dot":
        radius = max(2, int((7 if len(key.colours) == 1 else 5) * scale))
        for index, dot in enumerate(key.colours):
            centre = (x + int((index + 0.5) * length / len(key.colours)), y)
            cv2.circle(panel, centre, radius, tuple(int(c) for c in dot), -1, cv2.LINE_AA)
            cv2.circle(panel, centre, radius, INK, 1, cv2.LINE_AA)
    elif key.glyph == "arrow":
        cv2.arrowedLine(panel, (x, y), (x + length, y), colour, thick, cv2.LINE_AA, tipLength=0.4)
    else:
        cv2.line(panel, (x, y), (x + length, y), colour, thick, cv2.LINE_AA)


def _wrap(text: str, width: int, size: float, thickness: int) -> list[str]:
    lines, current = [], ""
    for word in text.split():
        candidate = f"{current} {word}".strip()
        if current and _text_width(candidate, size, thickness) > width:
            lines.append(current)
            current = word
        else:
            current = candidate
    return [*lines, current] if current else lines
