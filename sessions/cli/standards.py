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
    mark; with none, no standard is set and the message says why. From now on every verdict, page
    and report on the task judges against these marks as stored; sessions added later do not move
    them. Setting again makes a new version; the older ones stay listed (`vascsim standards show`).
    """
    import getpass

    from sessions.standards import set_standard

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
    from sessions.standards import standard_history

    catalog, _ = open_catalog()
    history = standard_history(catalog, study, task)
    if as_json:
        print_json([record.as_dict() for record in history])
        return
    if not history:
        click.echo(f"study {study!r}: no standard set" + (f" for {task}" if task else ""))
        return
    for record in history:
        click.echo(
            f"{record.task}: {record.label()}, by {record.set_by}"
            + (f": {record.note}" if record.note else "")
        )
        _print_marks(record)


def _print_marks(record) -> None:
    from metrics.registry import display_name

    for mark in record.marks:
        click.echo(
            f"  {display_name(mark['metric']):34s} passes at {mark['pass_if']} ({mark['better']} is better)"
        )
