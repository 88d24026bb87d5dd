"""`vascsim station`: a course station (instructions, live trials, feedback); the view options it
shares with `vascsim run`."""

from __future__ import annotations

from collections.abc import Callable
from functools import wraps
from typing import Any

import click

from sessions.cli.base import open_catalog, parse_size, user_errors

LIVE_DEVICES = ("mouse", "spacemouse", "openhaptics")
"""Devices a person moves: their sessions run on the real-time clock (and a live camera, below)."""


def is_camera(device: str) -> bool:
    return device == "camera" or device.startswith("camera:")


def is_live(device: str) -> bool:
    """Whether ``device`` is moved by a person now: a live device, or a camera (index or stream; a video
    file plays on a simulated clock unless asked for real time)."""
    if device in LIVE_DEVICES or device == "camera":
        return True
    spec = device.split(":", 1)[1] if is_camera(device) else ""
    return is_camera(device) and (spec.isdigit() or "://" in spec)


def station_device(_context, _parameter, value: str) -> str:
    """``--device`` of the station: a live device, a camera, or the scripted hand."""
    if value in (*LIVE_DEVICES, "scripted") or is_camera(value):
        return value
    raise click.BadParameter(
        f"{value!r}: one of {', '.join(LIVE_DEVICES)}, camera[:INDEX|URL|FILE], scripted"
    )


def chosen_view(view: str | None) -> str:
    """``--view`` as asked, else ``window`` where a display exists; a window asked for where no display
    answers is a usage error naming why."""
    from sessions.running.live import default_view
    from sim.devices.discovery import display_problem

    chosen = view or default_view()
    problem = display_problem() if chosen == "window" else None
    if problem is not None:
        raise click.UsageError(f"--view window needs a display: {problem}")
    return chosen


def view_options(command: Callable[..., Any]) -> Callable[..., Any]:
    """``--view``, ``--stereo``, ``--size`` and ``--handedness``, turned into one ``view`` argument (a
    :class:`sessions.running.live.LiveView`, or None for no window)."""

    @click.option(
        "--view",
        type=click.Choice(["window", "none"]),
        default=None,
        help="Show the live 3-D view in a window on this display, or not [default: window where a "
        "display exists, else none].",
    )
    @click.option(
        "--stereo",
        type=click.Choice(["anaglyph", "split", "crystal-eyes"]),
        default=None,
        help="Stereo for 3-D displays: red-cyan glasses, side-by-side halves, or shutter glasses "
        "(quad-buffered, where the graphics driver offers it).",
    )
    @click.option(
        "--size",
        default="960x540",
        show_default=True,
        callback=parse_size,
        help="The window's size in pixels, WIDTHxHEIGHT.",
    )
    @click.option(
        "--handedness",
        type=click.Choice(["right", "left"]),
        default="right",
        show_default=True,
        help="Which hand holds the needle holder: left swaps the wrist-turn keys of the keyboard "
        "and mouse and mirrors a hand-held device's axes (train both hands, as the paper asks); with "
        "--sub-device, left also swaps the two devices' instruments (the needle on --sub-device's, the "
        "forceps on --device's).",
    )
    @wraps(command)
    def wrapper(*args: Any, view: str | None, stereo, size, handedness, **kwargs: Any) -> Any:
        from sessions.running.live import LiveView
        from sessions.running.window import ViewSettings
        from sim.devices.mouse import MouseMapping

        chosen = chosen_view(view)
        live = None
        if chosen == "window":
            live = LiveView(ViewSettings(size=size, stereo=stereo), MouseMapping(handedness=handedness))
        return command(*args, view=live, handedness=handedness, **kwargs)

    return wrapper


def sub_device_option(command: Callable[..., Any]) -> Callable[..., Any]:
    """``--sub-device``: the subordinate hand's forceps on a second device."""
    from sessions.running.hands import SUB_DEVICES

    return click.option(
        "--sub-device",
        type=click.Choice(SUB_DEVICES),
        default="none",
        show_default=True,
        help="The subordinate hand's forceps (they hold the wound edge for the needle): a SpaceMouse (as "
        "in the source paper) or a second Touch; its first button closes the jaws. The jaws start open "
        "at the wound's edge beside the first entry mark. A scripted session brings its own.",
    )(command)


def stream_option(command: Callable[..., Any]) -> Callable[..., Any]:
    """``--stream-to URL``: the central recorder that receives each session as it is recorded (and the
    window's view, for the dashboard's live page), turned into one ``stream`` argument (a
    :class:`sessions.running.streaming.StreamTarget`, or None)."""

    @click.option(
        "--stream-to",
        default=None,
        metavar="URL",
        help="Stream each session, as it is recorded, to a central recorder (the dashboard's ingest, "
        "e.g. http://central:8000/ingest) with this station's token from VASCSIM_STATION_TOKEN; "
        "supervisors watch it on the dashboard's live page with the trainee's 3-D view. The local "
        "recording is kept whatever happens to the link; what the central recorder has not taken is "
        "sent by the next streamed session.",
    )
    @wraps(command)
    def wrapper(*args: Any, stream_to: str | None, **kwargs: Any) -> Any:
        from sessions.catalog.errors import CatalogError
        from sessions.running.streaming import StreamTarget, catalog_status, send_leftovers

        stream = None
        if stream_to is not None:
            try:
                stream = StreamTarget.from_environment(stream_to)
            except CatalogError as error:
                raise click.UsageError(str(error)) from None
            catalog, home = open_catalog()
            for line in send_leftovers(stream, home, catalog_status(catalog)):
                click.echo(f"note: left from an earlier session: {line}", err=True)
        return command(*args, stream=stream, **kwargs)

    return wrapper


def start_device(device: str) -> Callable[[], object] | None:
    """Opens the needle holder's device for the instruction screen (its buttons start the trial), where
    it has buttons to press."""
    from sim.devices.openhaptics import OpenHapticsDevice
    from sim.devices.spacemouse import SpaceMouse

    return {"spacemouse": SpaceMouse, "openhaptics": OpenHapticsDevice}.get(device)


@click.command()
@click.option("--study", required=True, help="Study (course) the trials belong to.")
@click.option("--participant", required=True, help="The trainee's participant code.")
@click.option(
    "--task", default="interrupted-stitch", show_default=True, help="Task to practise (`vascsim tasks`)."
)
@click.option(
    "--device",
    default="mouse",
    show_default=True,
    callback=station_device,
    help="The needle holder: mouse (keyboard and mouse), spacemouse (a rate control), openhaptics (a 3D "
    "Systems Touch), camera[:INDEX|URL|FILE] (a real needle holder with its printed marker cube, "
    "tracked by a webcam), or scripted (a demonstration).",
)
@click.option(
    "--trials",
    type=click.IntRange(1, 100),
    default=None,
    help="Stop after this many trials [default: until Q].",
)
@click.option(
    "--skill", type=click.FloatRange(0, 1), default=0.9, show_default=True, help="Scripted hand's skill."
)
@sub_device_option
@view_options
@stream_option
@user_errors
def station(study, participant, task, device, trials, skill, sub_device, view, handedness, stream) -> None:
    """Run a course station: instructions, a trial with the live view, feedback, the next trial.

    The instruction screen says what the task asks, what the marks mean, the time budget and the
    controls; SPACE (or a button of the SpaceMouse or Touch holding the needle) starts the trial
    after a 3-second countdown. The trial ends when every stitch is pulled through, when the trainee
    presses Esc or the device's second button (the trial is kept, complete and scored up to there),
    on Ctrl-C in this terminal (the same), or at twice the task's time budget. The feedback
    screen gives the verdict against the study's standard, each benchmark, what to work on and
    strengths; N starts the next trial, R renders a replay against the experts, Q quits. Trials
    count on as `vascsim run` counts them.
    """
    from sessions.replaying import replay_against_experts
    from sessions.running.hands import instruments
    from sessions.running.runner import SessionPlan, run_session
    from sessions.running.station import StationPlan, run_station
    from sessions.synthetic import pass_parameters
    from sessions.tasks import task_spec

    if view is None:
        raise click.UsageError("the station needs its window: run it on a display (--view window)")
    task_spec(task)  # an unknown task is refused before any window opens
    hands = instruments(device, sub_device, handedness)  # and a pairing of devices that cannot work
    catalog, home = open_catalog()
    clock = "realtime"
    parameters = (lambda trial: pass_parameters(skill, seed=trial)) if device == "scripted" else None

    def run_trial() -> str:
        plan = SessionPlan(study, participant, task, None, "practice", device, clock, sub_device, handedness)
        return run_session(catalog, home, plan, parameters, None, view=view, stream=stream)

    uids = run_station(
        catalog,
        home,
        StationPlan(study, participant, task, *hands),
        view,
        run_trial,
        replay=lambda uid: str(replay_against_experts(catalog, home, uid)),
        trials=trials,
        start_device=start_device(hands.needle),
    )
    click.echo(
        f"station closed: {len(uids)} trial(s) recorded and scored" + (f": {', '.join(uids)}" if uids else "")
    )
