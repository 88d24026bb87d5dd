"""A course station: instructions, a trial with the live view, feedback, and the next trial.

``vascsim station`` runs :func:`run_station`: the instruction screen (what the task asks, the marks,
the time budget, the controls, how to start), the space bar and a short countdown, the trial (a
real-time session with its window, :func:`sessions.running.runner.run_session`), then the feedback screen
(:func:`sessions.scoring.review.review_session`: the verdict against the study's standard, each benchmark,
what to work on, strengths) and the choice of the next trial, a replay of this one against the
experts, or quitting. Trials count on as ``vascsim run`` counts them. The screens' words are built
by pure functions (:func:`instruction_lines`, :func:`feedback_lines`), tested without a display.
"""

from __future__ import annotations

import time as clock
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from sessions.catalog import Catalog
from sessions.config import cache_dir
from sessions.running.live import LiveView
from sessions.running.screens import Line, Screen, wrapped
from sessions.scoring.review import SessionReview, experts_on_task, review_session
from sessions.tasks import TaskSpec, task_spec, warm_exit_columns
from sim.devices.base import DeviceError

COUNTDOWN_S = 3
START_KEYS = {"space": "start", "q": "quit", "Q": "quit", "Escape": "quit"}
FEEDBACK_KEYS = {"n": "next", "space": "next", "r": "replay", "q": "quit", "Q": "quit", "Escape": "quit"}

DEVICE_CONTROLS = {
    "mouse": [
        "Drag with the left mouse button: the needle holder follows the cursor across the view.",
        "Mouse wheel: forward (away from you) moves the needle towards the wall, back lifts it.",
        "Hold D or the right arrow: turn your wrist so the needle follows its own curve through the "
        "wall; A or the left arrow turns it back (swapped for a left hand).",
        "G: open or close the jaws (release the needle, and grasp it again at its tip to pull it "
        "through). Forces are shown on the gauge, not felt.",
    ],
    "spacemouse": [
        "The SpaceMouse is a rate control: push or tilt the cap and the needle holder moves at a speed "
        "set by how far you push (no force is felt). Its first button closes and opens the jaws; its "
        "second stops the trial.",
    ],
    "openhaptics": [
        "The Touch's stylus is the needle holder: you feel the wall. Its first button closes and opens "
        "the jaws; its second stops the trial.",
    ],
    "camera": [
        "Hold the needle holder with its marker cube towards the camera and suture over the table as "
        "over the wall: a millimetre of your hand is a millimetre of the needle. G (or the foot pedal) "
        "opens and closes the jaws: release the needle once it is through, grasp it again at its tip. "
        "No force is felt: the gauge shows it.",
        "If the camera loses the cube (your hand over it, turned away, out of view) the needle stays "
        "put and the strip says so; show the cube again and the needle glides back to your hand.",
    ],
    "scripted": ["A scripted hand places the stitch (a demonstration: no hand of yours is needed)."],
}
BUTTON_DEVICES = ("spacemouse", "openhaptics")
"""Needle-holder devices with buttons: one pressed and released starts the trial (:class:`ButtonStart`)."""
FORCEPS_CONTROLS = (
    "Your other hand holds the forceps ({device}): they start open at the wound's edge beside the first "
    "white dot. Its first button closes the jaws on the edge; move it towards you to lift (evert) the "
    "edge so the needle goes in square to it; press again to let go once the needle is through. Lift "
    "gently: pulled too far, the edge tears out of the jaws."
)
FORCEPS_DEVICE_NAMES = {"spacemouse": "the SpaceMouse, a rate control", "openhaptics": "the second Touch"}
CAMERA_FORCEPS_CONTROLS = (
    "Your other hand holds real forceps with their marker cube, in the camera's view: they start open at "
    "the wound's edge beside the first white dot. F (or a second pedal sending F) closes the jaws on the "
    "edge; lift it towards you (evert it) so the needle goes in square to it; F again lets go once the "
    "needle is through. Lift gently: pulled too far, the edge tears out of the jaws."
)


@dataclass(frozen=True)
class StationPlan:
    """Who practises what with which devices: study, participant code, task, the needle holder's device
    and the forceps' (None: one hand)."""

    study: str
    participant: str
    task: str
    device: str
    sub_device: str | None = None


def _clock(seconds: float) -> str:
    seconds = int(round(seconds))
    return f"{seconds // 60}:{seconds % 60:02d}"


NEEDS_FORCEPS = (
    "This task needs your other hand to evert the edge, and this station gives it no forceps: the needle "
    "cannot enter square (start the station with --sub-device spacemouse, openhaptics or camera)."
)


def instruction_lines(
    spec: TaskSpec, device: str, participant: str, standard_note: str = "", sub_device: str | None = None
) -> list[Line]:
    """What the instruction screen says for ``spec`` with ``device`` (and the forceps on ``sub_device``)."""
    stitches = spec.stitch_count
    lines = [Line(f"{spec.name}: next trial for {participant}", "title")]
    lines += wrapped(spec.description)
    lines.append(Line("The marks", "heading"))
    lines += wrapped(
        "White dots mark where each bite should go in (outer wall) and come out (inner wall); the dark "
        "red line is the wound's edge. Blue and orange dots show where your bites went in and came out; "
        "the grey line under the needle is its shadow on the wall (how high it is above it)."
    )
    lines.append(
        Line(
            f"Time budget {_clock(spec.time_budget_s)} for {stitches} stitch{'es' if stitches > 1 else ''}",
            "heading",
        )
    )
    lines.append(Line("Controls", "heading"))
    for text in DEVICE_CONTROLS.get(device.split(":")[0], []):
        lines += wrapped(text)
    if sub_device in FORCEPS_DEVICE_NAMES:
        lines += wrapped(FORCEPS_CONTROLS.format(device=FORCEPS_DEVICE_NAMES[sub_device]))
    elif sub_device == "camera":
        lines += wrapped(CAMERA_FORCEPS_CONTROLS)
    elif spec.eversion is not None:  # the task needs the other hand, and there is none
        lines += wrapped(NEEDS_FORCEPS, "bad-small")
    if standard_note:
        lines += wrapped(standard_note, "bad-small")
    lines.append(Line(""))
    start = "SPACE or a button: start" if device in BUTTON_DEVICES else "SPACE: start"
    lines.append(
        Line(f"{start} (3-second countdown)    Esc in the trial: stop (kept and scored)    Q: quit", "keys")
    )
    return lines


def feedback_lines(review: SessionReview) -> list[Line]:
    """What the feedback screen says about ``review``."""
    if review.verdict == "pass":
        lines = [Line(f"Trial {review.trial}: PASS, at the study's standard", "good")]
    elif review.verdict == "not yet":
        lines = [Line(f"Trial {review.trial}: not yet at the study's standard", "bad")]
    else:
        lines = [
            Line(f"Trial {review.trial}: recorded and scored (no standard to judge against yet)", "title")
        ]
    lines += wrapped(review.standard[:1].upper() + review.standard[1:] + ".")
    if review.benchmarks:
        lines.append(Line("Against the standard", "heading"))
        for bench in review.benchmarks:
            style = "body" if bench["passed"] is None else ("good" if bench["passed"] else "bad")
            for line in wrapped(bench["line"], indent="  "):
                lines.append(Line(line.text, style if style == "body" else style + "-small"))
    lines.append(Line("What to work on", "heading"))
    nothing = (
        "Nothing worse than the experts' middle half."
        if review.has_band
        else "Nothing to compare with yet: the experts' band appears once an expert of this study has "
        "recorded this task."
    )
    for item in review.work_on or [{"kind": "", "line": nothing}]:
        lines += wrapped((f"{item['kind']}: " if item["kind"] else "") + item["line"], indent="  ")
    if review.strengths:
        lines.append(Line("What you did well", "heading"))
        for item in review.strengths:
            lines += wrapped(item["line"], indent="  ")
    lines.append(Line(""))
    lines.append(Line("N or SPACE: next trial    R: replay against the experts    Q: quit", "keys"))
    return lines


class ButtonStart:
    """The instruction screen's start on the device itself: any of its buttons pressed, then released
    (a button still held would reach the trial, where the second one stops it). A device that stops
    answering leaves the space bar."""

    def __init__(self, device) -> None:
        self.device: object | None = device
        self._pressed = False

    def __call__(self) -> str | None:
        if self.device is None:
            return None
        try:
            buttons = self.device.read(clock.perf_counter()).buttons
        except DeviceError:
            self.device = None
            return None
        if buttons:
            self._pressed = True
            return None
        return "start" if self._pressed else None


def run_station(
    catalog: Catalog,
    home: Path,
    plan: StationPlan,
    view: LiveView,
    run_trial: Callable[[], str],
    replay: Callable[[str], str] | None = None,
    trials: int | None = None,
    start_device: Callable[[], object] | None = None,
) -> list[str]:
    """The station's loop (see the module docstring); ``run_trial()`` runs one session and returns its
    uid, ``replay(uid)`` renders it against the experts and returns where; ``trials`` bounds the loop;
    ``start_device()`` opens the needle holder's device for the instruction screen, so its button
    starts the trial as the space bar does (it is closed again before the trial opens it; a device
    that cannot be opened leaves the space bar, and the trial says why). Returns the uids of the
    trials run."""

    spec = task_spec(plan.task)
    uids: list[str] = []
    screen: Screen | None = Screen(view.settings, "instructions")
    try:
        while trials is None or len(uids) < trials:
            note = (
                ""
                if experts_on_task(catalog, plan.study, plan.task)
                else "No expert has recorded this task in this study yet: your trials are scored, not judged."
            )
            screen.show(instruction_lines(spec, plan.device, plan.participant, note, plan.sub_device))
            if _wait_to_start(screen, start_device) != "start":
                break
            # the countdown's waits solve what the trial's first exit will read (sessions.tasks)
            _countdown(screen, warm_exit_columns(spec, cache_dir(home)))
            screen.close()
            screen = None
            uid = run_trial()
            uids.append(uid)
            review = review_session(catalog, uid)
            screen = Screen(view.settings, "feedback")
            screen.show(feedback_lines(review))
            choice = screen.wait_for(FEEDBACK_KEYS)
            while choice == "replay" and replay is not None:
                screen.show([Line("Rendering the replay against the experts...", "heading")])
                where = replay(uid)
                screen.show([*feedback_lines(review), *wrapped(f"Replay written to {where}")])
                choice = screen.wait_for(FEEDBACK_KEYS)
            if choice != "next":
                break
            screen.close()
            screen = Screen(view.settings, "instructions")
    finally:
        if screen is not None:
            screen.close()
    return uids


def _wait_to_start(screen: Screen, start_device: Callable[[], object] | None) -> str:
    """SPACE, or the device's button where there is one to open."""
    device = None
    if start_device is not None:
        try:
            device = start_device()
        except DeviceError:
            device = None
    try:
        return screen.wait_for(START_KEYS, poll=ButtonStart(device) if device is not None else None)
    finally:
        if device is not None:
            device.close()


def _countdown(screen: Screen, prepare: Callable[[float], object] | None = None) -> None:
    """Three seconds counted down on the screen; ``prepare(until)`` works in each second's wait up to
    ``until`` (``time.monotonic()``), which the count keeps to."""
    for left in range(COUNTDOWN_S, 0, -1):
        screen.show(
            [Line(f"Starting in {left}", "title"), Line("Esc stops the trial; it is kept and scored.")]
        )
        until = clock.monotonic() + 1.0
        if prepare is not None:
            prepare(until)
        clock.sleep(max(0.0, until - clock.monotonic()))
