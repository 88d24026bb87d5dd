"""The station's screens between trials: instructions, the countdown, and the feedback.

Each screen is a window of its own in the session's process (titled ``vascsim: ...``), closed before a
trial starts: the trial's live view opens in the display process the run forks, and nothing of this
process's window system is carried into it. Text is drawn with VTK, the toolkit the live view uses.
"""

from __future__ import annotations

import textwrap
import time as clock
from collections.abc import Callable
from dataclasses import dataclass

from sessions.running.window import ViewSettings

WRAP = 118
"""Characters a line of body text is wrapped at (fits 960 px at the body's size, 15 px)."""


@dataclass(frozen=True)
class Line:
    """One line of a screen: its text and its style (``title``, ``heading``, ``good``, ``bad`` or
    ``body``)."""

    text: str
    style: str = "body"


STYLES = {
    "title": (26, True, (0.1, 0.1, 0.1)),
    "heading": (17, True, (0.15, 0.15, 0.15)),
    "good": (20, True, (0.05, 0.5, 0.15)),
    "bad": (20, True, (0.75, 0.1, 0.05)),
    "body": (15, False, (0.15, 0.15, 0.15)),
    "good-small": (15, True, (0.05, 0.5, 0.15)),
    "bad-small": (15, True, (0.75, 0.1, 0.05)),
    "keys": (16, True, (0.1, 0.25, 0.6)),
}


def wrapped(text: str, style: str = "body", indent: str = "") -> list[Line]:
    """``text`` wrapped to :data:`WRAP` characters, each line a :class:`Line`."""
    lines = textwrap.wrap(text, WRAP, initial_indent=indent, subsequent_indent=indent + "  ")
    return [Line(line, style) for line in lines or [""]]


def keyed_window(size: tuple[int, int], title: str, background: str, pressed: list[str]):
    """An open window with no camera interaction, each key pressed appended to ``pressed`` by name
    (``"closed"`` when the window is closed); returns its plotter and interactor."""
    import pyvista as pv
    from vtkmodules.vtkInteractionStyle import vtkInteractorStyleUser

    plotter = pv.Plotter(window_size=size, title=title)
    plotter.set_background(background)
    plotter.show(auto_close=False, interactive_update=True)
    plotter.set_background(background)  # opening the window applies the theme's own
    interactor = plotter.iren.interactor
    interactor.RemoveAllObservers()
    interactor.SetInteractorStyle(vtkInteractorStyleUser())
    interactor.AddObserver("KeyPressEvent", lambda caller, _: pressed.append(caller.GetKeySym()), 10.0)
    interactor.AddObserver("ExitEvent", lambda *_: pressed.append("closed"), 10.0)
    return plotter, interactor


def text_actor(text: str, style: tuple[int, bool, tuple[float, float, float]], position: tuple[int, int]):
    """A line of text at ``position`` (px from the bottom left) in ``style`` (size, bold, colour)."""
    from vtkmodules.vtkRenderingCore import vtkTextActor

    size, bold, colour = style
    actor = vtkTextActor()
    actor.SetInput(text)
    prop = actor.GetTextProperty()
    prop.SetFontSize(size)
    prop.SetBold(bold)
    prop.SetColor(*colour)
    actor.SetDisplayPosition(*position)
    return actor


KEYS_Y = 16
"""Where the ``keys`` line sits (px above the window's bottom edge)."""
TOP_MARGIN = 44
"""The first line's baseline below the window's top edge (px)."""


def _step(line: Line) -> float:
    """The space (px) a line takes below the one before it at full size, its heading gap included."""
    size = STYLES[line.style][0]
    gap = 8 if line.style == "heading" else 0
    return gap + size * 1.55 + (6 if line.style in ("title", "heading") else 0)


def layout(lines: list[Line], height: int) -> list[tuple[Line, int, int]]:
    """Each line with its baseline (px from the bottom) and font size: the flowing lines top to
    bottom, the ``keys`` lines pinned at :data:`KEYS_Y`. When the flowing lines would reach the keys
    line, their sizes and spacing shrink together until they clear it (a screen with more to say
    stays readable rather than drawing one line over another)."""
    flowing = [line for line in lines if line.style != "keys"]
    needed = sum(_step(line) for line in flowing)
    room = height - TOP_MARGIN - (KEYS_Y + 2 * STYLES["keys"][0])
    scale = min(1.0, room / needed) if needed > 0 else 1.0
    placed = [(line, KEYS_Y, STYLES["keys"][0]) for line in lines if line.style == "keys"]
    y = float(height - TOP_MARGIN)
    for line in flowing:
        gap = 8 * scale if line.style == "heading" else 0.0
        y -= gap
        placed.append((line, round(y), max(round(STYLES[line.style][0] * scale), 9)))
        y -= _step(line) * scale - gap
    return placed


class Screen:
    """A window of text lines and the keys that leave it (see the module docstring)."""

    def __init__(self, settings: ViewSettings, name: str) -> None:
        self.settings = settings
        self._pressed: list[str] = []
        title = f"{settings.title}: {name}"
        self.plotter, self._interactor = keyed_window(settings.size, title, "white", self._pressed)
        self._actors: list = []

    def show(self, lines: list[Line]) -> None:
        """Replace what the screen says with ``lines``, top to bottom (``keys`` lines at the bottom)."""
        renderer = self.plotter.renderer
        for actor in self._actors:
            renderer.RemoveViewProp(actor)
        self._actors = []
        for line, y, size in layout(lines, self.settings.size[1]):
            _, bold, colour = STYLES[line.style]
            actor = text_actor(line.text, (size, bold, colour), (28, y))
            renderer.AddViewProp(actor)
            self._actors.append(actor)
        self.plotter.render()

    def wait_for(
        self,
        keys: dict[str, str],
        timeout: float | None = None,
        poll: Callable[[], str | None] | None = None,
    ) -> str:
        """Block until one of ``keys`` (key name -> choice) is pressed, the window is closed
        (``"quit"``), ``poll()`` (asked every 20 ms: a device's buttons) returns a choice, or
        ``timeout`` seconds pass (``"timeout"``); returns the choice."""
        self._pressed.clear()
        deadline = None if timeout is None else clock.monotonic() + timeout
        while True:
            self._interactor.ProcessEvents()
            chosen = poll() if poll is not None else None
            if chosen is not None:
                return chosen
            for key in self._pressed:
                if key == "closed":
                    return "quit"
                if key in keys:
                    return keys[key]
            self._pressed.clear()
            if deadline is not None and clock.monotonic() > deadline:
                return "timeout"
            clock.sleep(0.02)

    def close(self) -> None:
        self.plotter.close()
