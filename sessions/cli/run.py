"""`vascsim run`: one session through device, simulator, recorder and catalog."""

from __future__ import annotations

import click

from metrics.registry import REGISTRY
from metrics.units import shown
from sessions.cli.base import (
    open_catalog,
    print_json,
    stderr_console,
    user_errors,
)
from sessions.cli.lrs import push_after_scoring


@click.command()
@click.option("--study", required=True, help="Study the session belongs to.")
@click.option("--participant", required=True, help="Participant code.")
@click.option("--task", default="wall-stitch", show_default=True, help="Task / scenario.")
@click.option(
    "--device",
    default="scripted",
    show_default=True,
    help="scripted, spacemouse, openhaptics, or replay:SESSION to play a recorded session back.",
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
    "--duration", type=click.FloatRange(0.1, 7200), default=None, help="Seconds (needed for live devices)."
)
@click.option(
    "--realtime", is_flag=True, help="Real-time clock (a person at the device); default simulated time."
)
@click.option("--json", "as_json", is_flag=True, help="Print the session's metrics as JSON.")
@user_errors
def run(study, participant, task, device, skill, phase, duration, realtime, as_json) -> None:
    """Run one session: device + simulator + recorder + catalog entry, then scoring.

    The catalog row is written as 'running' first and becomes 'complete' only when
    the streams are closed and checksummed; Ctrl-C or an error keeps the data and
    marks the session 'failed'; after a crash, `vascsim recover` restores it.
    """
    from sessions.runner import SessionPlan, run_session
    from sessions.store import CatalogStore
    from sessions.synthetic import pass_parameters

    catalog, home = open_catalog()
    clock = "realtime" if realtime or device in ("spacemouse", "openhaptics") else "simulated"
    if duration is None and device in ("spacemouse", "openhaptics"):
        raise click.UsageError(f"--duration is needed with device {device!r} (it runs until stopped)")
    plan = SessionPlan(study, participant, task, None, phase, device, clock)  # next trial, allocated
    parameters = (lambda trial: pass_parameters(skill, seed=trial)) if device == "scripted" else None
    with stderr_console().status(f"running {participant} on {device}..."):
        uid = run_session(catalog, home, plan, parameters, duration)
    facts = CatalogStore(catalog).session_facts(uid)
    trial, values = facts.session.trial, facts.metrics
    if as_json:
        print_json({"session": uid, "trial": trial, "metrics": values})
    else:
        click.echo(f"session {uid} ({participant}, trial {trial}) complete and scored")
        for name, value in values.items():
            unit = REGISTRY[name].unit if name in REGISTRY else ""
            click.echo(f"  {name:28s} {shown(value, unit):>14s}")
    push_after_scoring(catalog, home, [uid])
