"""`vascsim participants ...`: pseudonymous participants of a study."""

from __future__ import annotations

import click
import pandas as pd

from sessions.cli.base import (
    open_catalog,
    open_store,
    print_frame,
    print_json,
    user_errors,
)


@click.group()
def participants() -> None:
    """Pseudonymous participants of a study."""


@participants.command("add")
@click.argument("code")
@click.option("--study", required=True, help="Study the participant joins.")
@click.option("--level", default="", help="Self-reported level, e.g. expert, trainee, novice.")
@click.option("--group", "group_label", default="", help="Group label analysed (default: the level).")
@click.option("--years", type=click.FloatRange(0, 80), default=None, help="Years of surgical experience.")
@click.option(
    "--handedness", type=click.Choice(["right", "left", "ambidextrous"]), default="right", show_default=True
)
@user_errors
def participants_add(code: str, study: str, level: str, group_label: str, years, handedness: str) -> None:
    """Add participant CODE (a pseudonym; never a name) to a study."""
    store, _ = open_store()
    store.add_participant(study, code, level, group_label, years, handedness)
    click.echo(f"participant {code} added to {study}")


@participants.command("list")
@click.option("--study", required=True, help="Study to list.")
@click.option("--json", "as_json", is_flag=True, help="Print as JSON.")
@user_errors
def participants_list(study: str, as_json: bool) -> None:
    """List a study's participants."""

    store, _ = open_store()
    columns = ("code", "level", "group", "years", "handedness", "synthetic", "sessions")
    rows = [{c: getattr(p, c) for c in columns} for p in store.participants(study)]
    if as_json:
        print_json(rows)
        return
    print_frame(pd.DataFrame(rows), f"Participants of {study}")


@participants.command("export")
@click.option("--study", required=True, help="The study whose participants' progress is exported.")
@click.option(
    "-o",
    "--output",
    "output",
    type=click.Path(dir_okay=False),
    required=True,
    help="progress.xlsx or progress.csv.",
)
@user_errors
def participants_export(study: str, output: str) -> None:
    """Each participant's progress and status as an Excel workbook or CSV: sessions, dates, passes,
    status in words, and each benchmarked metric's latest value beside its benchmark (units and
    direction in the headers)."""
    from pathlib import Path

    from sessions.exchange.progress import progress_table, write_progress

    catalog, _ = open_catalog()
    table = progress_table(catalog, study)
    path = write_progress(table, Path(output), study)
    click.echo(f"wrote {path} ({len(table)} participants)")
