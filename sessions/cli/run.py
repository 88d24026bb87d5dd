"""`vascsim run`: one session through device, simulator, recorder and catalog."""

from __future__ import annotations

import click

from sessions.cli.base import (
    open_catalog,
    print_json,
    stderr_console,
    user_errors,
)
from sessions.cli.lrs import push_after_scoring
from sessions.cli.station import is_live, stream_option, sub_device_option, view_options


@click.command()
@click.option("--study", required=True, help="Study the session belongs to.")
@click.option("--participant", required=True, help="Participant code.")
@click.option(
    "--task",
    default=None,
    help="Task to run (`vascsim tasks`) [default: the task of the study's declared analysis, else "
    "interrupted-stitch].",
)
@click.option(
    "--device",
    default="scripted",
    show_default=True,
    help="scripted, mouse (keyboard and mouse in the live window), spacemouse, openhaptics, "
    "camera[:INDEX|URL|FILE] (real instruments with printed markers; a video file replays through the "
    "same tracking), or replay:SESSION to play a recorded session back.",
)
@click.option(
    "--skill",
    type=click.FloatRange(0, 1),
    default=0.9,
    show_default=True,
    help="Scripted device: skill of the pass (0-1).",
)
@click.option("--phase", type=click.Choice(["practice", "retention"]), default="practice", show_default=True)
@click.option(
    "--duration",
    type=click.FloatRange(0.1, 7200),
    default=None,
    help="Seconds [default: a scripted pass's own length (a longer --duration still ends with the "
    "script); a live device until the task is done, Esc or Ctrl-C, at most twice the task's time "
    "budget].",
)
@click.option(
    "--realtime", is_flag=True, help="Real-time clock (a person at the device); default simulated time."
)
@click.option(
    "--json", "as_json", is_flag=True, help="Print the session's verdict, feedback and metrics as JSON."
)
@sub_device_option
@view_options
@stream_option
@user_errors
def run(
    study,
    participant,
    task,
    device,
    skill,
    phase,
    duration,
    realtime,
    as_json,
    sub_device,
    view,
    handedness,
    stream,
) -> None:
    """Run one session: device + simulator + recorder + catalog entry, then scoring.

    A real-time session opens the live 3-D view in a window where a display exists (--view). The
    catalog row is written as 'running' first and becomes 'complete' only when the streams are
    closed and checksummed; stopping early (Esc in the window, Ctrl-C here) keeps a complete session,
    scored up to where it stopped; an error keeps the data and marks the session 'failed'; after a
    crash, `vascsim recover` restores it. Ends with the verdict against the study's standard and the
    three things to work on first (--json: everything).
    """
    from sessions.catalog.store import CatalogStore
    from sessions.running.runner import SessionPlan, run_session
    from sessions.scoring.review import experts_on_task, review_session
    from sessions.status import SCRIPTED_DEVICE
    from sessions.synthetic import scripted_hands

    catalog, home = open_catalog()
    with catalog.session() as orm:  # who and where first: a wrong code is the one line said
        catalog.participant(orm, catalog.study(orm, study), participant)
    task = task or default_task(catalog, study)
    if not experts_on_task(catalog, study, task):  # said before the run, not discovered after it
        click.echo(
            f"note: no expert of study {study!r} has a scored session of {task} yet: this session is "
            "recorded and scored, with no standard to judge it against",
            err=True,
        )
    if device == SCRIPTED_DEVICE:
        click.echo("note: a scripted pass, not a person's hand: the session is marked synthetic", err=True)
    clock = "realtime" if realtime or is_live(device) else "simulated"
    plan = SessionPlan(study, participant, task, None, phase, device, clock, sub_device, handedness)
    parameters = (lambda trial: scripted_hands(skill, seed=trial)) if device == "scripted" else None
    with stderr_console().status(f"running {participant} on {device}..."):
        live_view = view if clock == "realtime" else None
        uid = run_session(catalog, home, plan, parameters, duration, view=live_view, stream=stream)
    facts = CatalogStore(catalog).session_facts(uid)
    review = review_session(catalog, uid)
    if as_json:
        print_json(
            {"session": uid, "trial": facts.session.trial, **review.as_dict(), "metrics": facts.metrics}
        )
    else:
        for line in review_lines(review, participant):
            click.echo(line)
    push_after_scoring(catalog, home, [uid])


DEFAULT_TASK = "interrupted-stitch"
"""The task a run practises when neither --task nor the study's declared analysis names one."""


def default_task(catalog, study: str) -> str:
    """The task of the study's declared analysis, else :data:`DEFAULT_TASK`."""
    from sessions.scoring.analysis import declared_settings

    settings, _, _ = declared_settings(catalog, study)
    return settings.task or DEFAULT_TASK


def review_lines(review, participant: str) -> list[str]:
    """The terminal's closing lines: the session, its verdict, and the three things to work on first."""
    verdicts = {"pass": "PASS (at the study's standard)", "not yet": "NOT YET at the study's standard"}
    verdict = f"verdict: {verdicts.get(review.verdict, 'no standard yet')}; {review.standard}"
    lines = [
        f"session {review.uid} ({participant}, trial {review.trial}) complete and scored",
        click.wrap_text(verdict, 78, subsequent_indent="  "),
    ]
    lines += [
        click.wrap_text(b["line"], 78, initial_indent="  ", subsequent_indent="    ")
        for b in review.benchmarks
    ]
    lines.append("work on:" if review.work_on else "work on: nothing worse than the experts' middle half")
    for k, item in enumerate(review.work_on[:3], 1):
        text = f"{k}. {item['kind']}: {item['line']}"
        lines.append(click.wrap_text(text, 78, initial_indent="  ", subsequent_indent="     "))
    lines.append(f"all metrics: vascsim sessions show {review.uid}")
    return lines
