"""`vascsim standards ...`: a study's pass marks, set once per task and versioned."""

from __future__ import annotations

import click

from sessions.cli.base import open_catalog, print_json, user_errors


@click.group()
def standards() -> None:
    """A study's standards: pass marks set once per task, versioned, never recomputed."""


@standards.command("set")
@click.option("--study", required=True, help="The study (course) whose standard is set.")
@click.option("--task", required=True, help="The task the marks are for (`vascsim tasks`).")
@click.option("--by", "author", default=None, help="Who sets it (default: the login name).")
@click.option("--note", default="", help="Why this version (e.g. 'two more experts recorded').")
@click.option("--json", "as_json", is_flag=True, help="Print the standard as JSON.")
@user_errors
def standards_set(study: str, task: str, author: str | None, note: str, as_json: bool) -> None:
    """Set a new version of STUDY's standard on TASK from its declared analysis today.

    Only metrics on which the experts do better (AUC interval above 0.5, or a declared reason) get a
    mark; with none, no standard is set and the message says why. Sessions added later do not move
    the marks. The first version judges the task's sessions so far; a later one judges the sessions
    recorded from when it is set, and every session keeps the verdict it was given (re-judge the
    history under the newest with `vascsim standards rejudge`). The older versions stay listed
    (`vascsim standards show`).
    """
    import getpass

    from sessions.scoring.setting import set_standard

    catalog, _ = open_catalog()
    record = set_standard(catalog, study, task, author or getpass.getuser(), note)
    if as_json:
        print_json(record.as_dict())
        return
    click.echo(f"study {study!r}, {task}: {record.label()}")
    _print_marks(record)


@standards.command("show")
@click.option("--study", required=True, help="The study whose standards are shown.")
@click.option("--task", default=None, help="Only this task's.")
@click.option("--json", "as_json", is_flag=True, help="Print every version as JSON.")
@user_errors
def standards_show(study: str, task: str | None, as_json: bool) -> None:
    """Every version of STUDY's standards, oldest first, with their marks (the newest is in force)."""
    from sessions.scoring.standards import standard_history

    catalog, _ = open_catalog()
    history = standard_history(catalog, study, task)
    if as_json:
        print_json([record.as_dict() for record in history])
        return
    if not history:
        click.echo(f"study {study!r}: no standard set" + (f" for {task}" if task else ""))
        return
    from sessions.scoring.verdicts import rejudgements

    for record in history:
        click.echo(
            f"{record.task}: {record.label()}, by {record.set_by}"
            + (f": {record.note}" if record.note else "")
        )
        _print_marks(record)
        for entry in rejudgements(catalog, study, record.task):
            if entry["version"] == record.version:
                when = entry["at"][:16].replace("T", " ")
                click.echo(
                    f"  re-judged {when} UTC by {entry['by']}: {entry['sessions']} sessions, "
                    f"{entry['changed']} verdict(s) changed; why: {entry['reason']}"
                )


@standards.command("rejudge")
@click.option("--study", required=True, help="The study whose history is re-judged.")
@click.option("--task", required=True, help="The task whose sessions are re-judged.")
@click.option("--reason", required=True, help="Why (kept in the standard's log, shown by `standards show`).")
@click.option("--by", "author", default=None, help="Who re-judges (default: the login name).")
@click.option("--json", "as_json", is_flag=True, help="Print the result as JSON.")
@user_errors
def standards_rejudge(study: str, task: str, reason: str, author: str | None, as_json: bool) -> None:
    """Judge every scored session of TASK in STUDY under the newest standard, replacing the verdicts
    they kept from earlier versions. Logged: who, when, why, and how many verdicts changed."""
    import getpass

    from sessions.scoring.setting import rejudge

    catalog, _ = open_catalog()
    result = rejudge(catalog, study, task, author or getpass.getuser(), reason)
    if as_json:
        print_json({"version": result.version, "sessions": result.sessions, "changed": result.changed})
        return
    click.echo(
        f"study {study!r}, {task}: {result.sessions} sessions judged under v{result.version}; "
        f"{result.changed} verdict(s) changed"
    )


def _print_marks(record) -> None:
    from metrics.session.registry import display_name

    for mark in record.marks:
        click.echo(
            f"  {display_name(mark['metric']):34s} passes at {mark['pass_if']} ({mark['better']} is better)"
        )
