"""Reads a blind render frame by frame against what the blind render may show
(:mod:`metrics.replay.blind`): the strip and the key identical in every frame to the blind ones
(no name, code, trial, readout or verdict can be written there), and a 3-D view with no expert
ghost green, no stress-map orange and no verdict-coloured bite."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from metrics.replay import blind
from metrics.replay.hud import FrameLayout, draw_key, draw_strip

TEXT_TOLERANCE = 64
"""A decoded pixel of the strip or key may differ from the drawn one by this much (H.264 at text
edges) and still count as the same."""


def decoded_frames(video: Path | bytes) -> list[np.ndarray]:
    import io

    import av

    source = io.BytesIO(video) if isinstance(video, bytes) else str(video)
    with av.open(source) as container:
        return [frame.to_ndarray(format="rgb24") for frame in container.decode(video=0)]


def expected_panels(
    size: tuple[int, int], marks: bool, wound: bool, forceps: bool = False
) -> tuple[FrameLayout, np.ndarray, np.ndarray]:
    """The blind layout, strip and key at ``size`` for a session with/without marks, a wound and the
    subordinate hand's forceps."""
    from sim.render import stress_colours

    title, lines = blind.readout()
    layout = FrameLayout.of(size, 1, [(title, lines)])
    strip = draw_strip(layout.view_size[0], layout.strip, title, lines, layout.scale)
    key = draw_key(
        layout.height,
        layout.panel,
        layout.scale,
        None,
        stress_colours(),
        blind.blind_keys(marks, wound, forceps),
    )
    return layout, strip, key


def judged_pixels(view: np.ndarray) -> dict[str, int]:
    """How many pixels of a 3-D view carry a colour the blind render never draws: the expert's
    green (ghost path and needle; an on-mark bite) and the stress map's or a near-mark bite's orange."""
    rgb = view.astype(float) / 255
    high, low = rgb.max(axis=2), rgb.min(axis=2)
    saturation = np.where(high > 0, (high - low) / np.maximum(high, 1e-9), 0)
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    strong = (saturation > 0.45) & (high > 0.35)
    green = strong & (g >= r) & (g > b)
    orange = strong & (r > g) & (g > b) & (g - b > 0.25 * (r - b))  # hue about 15-60 degrees
    return {"green": int(green.sum()), "orange": int(orange.sum())}


def blind_problems(
    frames: list[np.ndarray],
    marks: bool | None = None,
    wound: bool | None = None,
    forceps: bool | None = None,
) -> list[str]:
    """What in ``frames`` a blinded rater must not see (empty when the video is blind). ``marks``,
    ``wound`` and ``forceps``: whether the session's task has target marks and a wound, and the session
    a subordinate hand (None: whichever blind key the first frame carries)."""
    if marks is None or wound is None or forceps is None:
        combinations = [(m, w, f) for m in (False, True) for w in (False, True) for f in (False, True)]
        readings = [blind_problems(frames[:1], *combination) for combination in combinations]
        marks, wound, forceps = combinations[min(range(len(combinations)), key=lambda k: len(readings[k]))]
    height, width = frames[0].shape[:2]
    layout, strip, key = expected_panels((width, height), marks, wound, forceps)
    view_width = layout.view_size[0]
    problems = []
    for index, frame in enumerate(frames):
        shown_strip = frame[: layout.strip, :view_width].astype(int)
        shown_key = frame[:, width - layout.panel :].astype(int)
        for name, shown, drawn in (("strip", shown_strip, strip), ("key", shown_key, key)):
            off = int((np.abs(shown - drawn.astype(int)).max(axis=2) > TEXT_TOLERANCE).sum())
            if off > 0.001 * drawn.shape[0] * drawn.shape[1]:
                problems.append(f"frame {index}: the {name} differs from the blind one at {off} pixels")
        for colour, count in judged_pixels(frame[layout.strip :, :view_width]).items():
            if count > 3:
                problems.append(f"frame {index}: {count} {colour} pixels in the view")
    return problems
