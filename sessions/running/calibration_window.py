"""The live calibration's window (``vascsim calibrate --live`` on a display): the camera's picture with
the board's corners as they are found, the five views a calibration needs with how many of each are
taken, and, in large letters, which way to turn the board next.

The person holding the board looks at the screen, not at a terminal: the checklist and the next
instruction change as views are kept. Esc or Q in the window gives up (nothing is written).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from sessions.running.screens import keyed_window, text_actor
from sim.errors import VascsimError
from sim.tracking.guided import KINDS, VIEWS_PER_KIND

HOW_TO_SHOW = {
    "square-on": "Hold the board square to the camera, filling much of the picture",
    "tilted left": "Turn the board's left edge away from you (about 25 deg)",
    "tilted right": "Turn the board's right edge away from you (about 25 deg)",
    "tilted up": "Tip the board's top edge away from you (about 25 deg)",
    "tilted down": "Tip the board's bottom edge away from you (about 25 deg)",
}
"""What the person holding the board does to give a view of each kind."""
TITLE = "vascsim: camera calibration"
COLUMN_PX, BAND_PX = 290, 64
"""The checklist's column on the right and the instruction's band at the bottom (px)."""


class CalibrationCancelled(VascsimError):
    """The person gave up in the window (Esc or Q)."""


def guidance_lines(counts: dict[str, int], found_corners: int) -> list[tuple[str, str]]:
    """What the window says, as (text, style) pairs: the next instruction, the checklist, the board."""
    missing = [kind for kind in KINDS if counts.get(kind, 0) < VIEWS_PER_KIND]
    lines = [(HOW_TO_SHOW[missing[0]] if missing else "Every view is taken: calibrating", "next")]
    for kind in KINDS:
        done = min(counts.get(kind, 0), VIEWS_PER_KIND)
        mark = "done" if done == VIEWS_PER_KIND else f"{done} of {VIEWS_PER_KIND}"
        lines.append((f"{kind}: {mark}", "done" if done == VIEWS_PER_KIND else "todo"))
    board = f"board: {found_corners} corners found" if found_corners else "board: not found in the picture"
    lines.append((board, "todo" if found_corners else "warn"))
    lines.append(("Esc: give up (nothing is written)", "keys"))
    return lines


STYLES = {
    "next": (24, True, (1.0, 0.85, 0.1)),
    "done": (17, True, (0.3, 0.9, 0.4)),
    "todo": (17, False, (0.95, 0.95, 0.95)),
    "warn": (17, True, (1.0, 0.45, 0.35)),
    "keys": (15, False, (0.8, 0.85, 1.0)),
}


class CalibrationWindow:
    """The window (see the module docstring): :meth:`show` after each frame; raises
    :class:`CalibrationCancelled` when the person gives up."""

    def __init__(self, size: tuple[int, int] = (960, 540)) -> None:
        self.size = size
        self._keys: list[str] = []
        self.plotter, self._interactor = keyed_window(size, TITLE, "black", self._keys)
        self._picture = None
        self._texts: list = []

    def show(self, frame: NDArray[np.uint8], counts: dict[str, int], corners: NDArray | None) -> None:
        """Draw ``frame`` (grey or BGR) with the board's ``corners`` (n, 2 px) and the guidance."""
        self._interactor.ProcessEvents()
        if any(key in ("Escape", "q", "Q", "closed") for key in self._keys):
            raise CalibrationCancelled("the calibration was given up in its window; nothing was written")
        self._keys.clear()
        self._draw_picture(self._marked(frame, corners))
        self._draw_text(guidance_lines(counts, 0 if corners is None else len(corners)))
        self.plotter.render_window.Render()

    @staticmethod
    def _marked(frame: NDArray[np.uint8], corners: NDArray | None) -> NDArray[np.uint8]:
        import cv2

        picture = cv2.cvtColor(frame, cv2.COLOR_GRAY2RGB) if frame.ndim == 2 else frame[..., ::-1].copy()
        for x, y in np.asarray(corners if corners is not None else []).reshape(-1, 2):
            cv2.circle(picture, (int(round(x)), int(round(y))), 4, (40, 220, 80), -1)
        return picture

    def _draw_picture(self, picture: NDArray[np.uint8]) -> None:
        """The picture as a flat image filling the window's left part, at parallel projection: an image
        actor (one textured quad: the window's whole frame 31 ms under software rendering, where the same
        picture as a coloured mesh of its 0.5 million pixels made it 282 ms)."""
        import pyvista as pv
        from vtkmodules.vtkRenderingCore import vtkImageActor

        height, width = picture.shape[:2]
        rgb = np.ascontiguousarray(picture[::-1]).reshape(-1, 3)  # VTK's rows run bottom up
        if self._picture is None or self._picture.dimensions[:2] != (width, height):
            self.plotter.clear_actors()
            self._picture = pv.ImageData(dimensions=(width, height, 1))
            self._picture.point_data.set_scalars(rgb, "rgb")
            actor = vtkImageActor()
            actor.GetMapper().SetInputData(self._picture)
            self.plotter.add_actor(actor, reset_camera=False)
            self.plotter.view_xy()
            self.plotter.enable_parallel_projection()
            # the picture in the top left, beside the checklist's column and above the instruction
            window_width, window_height = self.size
            per_pixel = min((window_width - COLUMN_PX) / width, (window_height - BAND_PX) / height)
            half_width, half_height = window_width / (2 * per_pixel), window_height / (2 * per_pixel)
            camera = self.plotter.camera
            camera.focal_point = (half_width, height - half_height, 0.0)
            camera.position = (half_width, height - half_height, 1000.0)
            camera.parallel_scale = half_height
        else:
            self._picture.point_data["rgb"][:] = rgb
            self._picture.GetPointData().GetScalars().Modified()
            self._picture.Modified()

    def _draw_text(self, lines: list[tuple[str, str]]) -> None:
        renderer = self.plotter.renderer
        for actor in self._texts:
            renderer.RemoveViewProp(actor)
        self._texts = []
        width, height = self.size
        y = height - 40
        for text, style in lines:
            if style == "next":  # the instruction under the picture, large
                actor = text_actor(text, STYLES[style], (16, 16))
            else:  # the checklist's column, right of the picture
                actor = text_actor(text, STYLES[style], (width - COLUMN_PX + 12, y))
                y -= int(STYLES[style][0] * 1.8)
            actor.GetTextProperty().SetBackgroundColor(0.0, 0.0, 0.0)
            actor.GetTextProperty().SetBackgroundOpacity(0.6)
            renderer.AddViewProp(actor)
            self._texts.append(actor)

    def close(self) -> None:
        self.plotter.close()
