"""The command line's common ground: the main group, one-line errors, the catalog, tables and JSON.

Every command module (:mod:`sessions.cli`) builds on these; the front-end stays thin over the
domain layer (catalog, runner, analysis).
"""

from __future__ import annotations

import json
import shlex
import sys
from collections.abc import Callable
from functools import wraps
from pathlib import Path
from typing import Any

import click
import numpy as np
import pandas as pd

from sim.errors import VascsimError

LISTED_BY = {
    "study": "vascsim studies list",
    "session": "vascsim sessions list",
    "participant": "vascsim participants list --study STUDY",
    "task": "vascsim tasks list",
    "user": "vascsim users list",
}
"""Where the CLI lists each kind of thing the catalog can fail to find (the library's messages say
only what is missing)."""


REMEDIES = {
    "recover": "run `vascsim recover {}` first",
    "score": "run `vascsim score --study {}` first",
    "new-key": "make one with `vascsim keys new`",
    "replace-rating": "pass --replace to replace that rating",
    "choose-task": "pass --task, one of {}",
    "choose-versus": "pass --vs SESSION or --vs-group GROUP",
    "choose-device": "pass --device {}",
    "declare-group": "declare another with `vascsim studies groups {} --add NAME`",
    "calibrate": "calibrate it with `vascsim calibrate --live` (or from photos: `vascsim calibrate`)",
}
"""A domain error's remedy (:attr:`sim.errors.VascsimError.remedy`) as the command that applies it."""

LISTS = ("choose-task", "choose-device")
"""Remedies whose value is a list to choose from, not an argument to paste (the rest are quoted)."""


def remedy_in_words(error: VascsimError) -> str:
    """ "; " and the CLI's words for the error's remedy, or "" when it names none."""
    remedy = getattr(error, "remedy", None)
    if remedy is None or remedy[0] not in REMEDIES:
        return ""
    value = remedy[1] if remedy[0] in LISTS else shlex.quote(str(remedy[1]))  # a command pastes as shown
    return "; " + REMEDIES[remedy[0]].format(value)


def user_errors(command: Callable[..., Any]) -> Callable[..., Any]:
    """Turn vascsim errors into a one-line message and exit status 1 (no traceback)."""

    @wraps(command)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return command(*args, **kwargs)
        except VascsimError as error:
            from sessions.catalog import NotFound

            hint = LISTED_BY.get(getattr(error, "kind", None)) if isinstance(error, NotFound) else None
            said = f"vascsim: error: {error}" + (f" (list them with `{hint}`)" if hint else "")
            click.echo(said + remedy_in_words(error), err=True)
            sys.exit(1)

    return wrapper


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="vascsim")
def main() -> None:
    """vascsim: a haptic vascular-suturing simulator and assessment platform.

    Run `vascsim demo` for a tour on built-in data; `vascsim COMMAND --help`
    explains each command. Data lives in VASCSIM_HOME (default
    ~/.local/share/vascsim); VASCSIM_DATABASE_URL selects a PostgreSQL catalog.
    """
    from sessions.config import prepare_rendering

    prepare_rendering()


def open_catalog():
    from sessions.catalog import Catalog
    from sessions.config import data_home, database_url

    home = data_home()
    catalog = Catalog(database_url(home))
    click.get_current_context().call_on_close(catalog.close)  # no pooled connection outlives the command
    return catalog, home


def open_store():
    """(the catalog's store, the data home): what a command reads and changes goes through the store."""
    from sessions.catalog.store import CatalogStore

    catalog, home = open_catalog()
    return CatalogStore(catalog), home


def progress_bar(transient: bool = False):
    """A progress bar on stderr; a transient one vanishes when done and stays silent off a terminal."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
    from rich.table import Column

    console = stderr_console()
    return Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(table_column=Column(no_wrap=True, min_width=5)),
        TimeElapsedColumn(table_column=Column(no_wrap=True, min_width=7)),  # never "0:01:…"
        # what is running now gives way first: cut at the end, on one line
        TextColumn(
            "{task.fields[last]}", table_column=Column(no_wrap=True, overflow="ellipsis", max_width=36)
        ),
        transient=transient,
        disable=transient and not console.is_terminal,
        console=console,
    )


def stderr_console():
    from rich.console import Console

    return Console(stderr=True)


def print_frame(frame, title: str, caption: str | None = None) -> None:
    """A table of ``frame`` under ``title`` with ``caption`` after it, every line within the console's
    width (80 columns when not a terminal): names and values are never cut."""
    from rich import box
    from rich.console import Console
    from rich.table import Table

    # the title and caption are wrapped at the console's width as text (a table title is centred
    # over the table and cropped where the table is narrower than it)
    console = Console()
    console.print(title, style="italic", overflow="fold")
    table = Table(box=box.SIMPLE_HEAD, padding=(0, 1), collapse_padding=True, pad_edge=False)
    for k, column in enumerate(frame.columns):
        # names are never cut and no value ends in an ellipsis: a short value keeps its width, a long
        # one wraps at its spaces ("0.83" over "(0.61-0.95)")
        widest = max([len(cell_text(v)) for v in frame[column]] or [0])
        short = max([len(part) for v in frame[column] for part in cell_text(v).split()] or [0])
        table.add_column(str(column), no_wrap=k == 0, overflow="fold", min_width=min(widest, max(short, 4)))
    for row in frame.itertuples(index=False):
        table.add_row(*[cell_text(v) for v in row])
    console.print(table)
    if caption:
        console.print(caption, style="dim", overflow="fold")


def cell_text(value) -> str:
    if value is None or value is pd.NA:
        return ""
    if isinstance(value, float):
        return "" if value != value else f"{value:.4g}"
    if isinstance(value, bool | np.bool_):
        return "yes" if value else "no"
    return str(value)


def print_json(data) -> None:
    click.echo(json.dumps(data, indent=2, default=_json_default))


def _json_default(value):
    if isinstance(value, np.generic):
        return value.item()
    return str(value)


def analysis_options(groups, level, metric_names, rule, consecutive=None) -> dict:
    from sessions.catalog import CatalogError

    options: dict = {"level": level, "benchmark_rule": rule, "consecutive_passes": consecutive}
    if groups is not None:
        names = tuple(part.strip().lower() for part in groups.split(","))  # groups are lower-case
        if len(names) != 2:
            raise CatalogError(f"--groups needs two comma-separated groups, skilled first; got {groups!r}")
        options["groups"], options["skilled_group"] = names, names[0]
    if metric_names is not None:
        options["metrics"] = tuple(part.strip() for part in metric_names.split(",") if part.strip())
    return {k: v for k, v in options.items() if v is not None}


class MissingInput(VascsimError, FileNotFoundError):
    """A file or folder named on the command line is not there (or is the other kind)."""


def existing_path(path: str, what: str, folder: bool = False) -> Path:
    """``path`` as a Path when it is an existing file (``folder``: directory); else a one-line
    :class:`MissingInput` naming it (not click's usage text)."""
    found = Path(path)
    if folder and not found.is_dir():
        raise MissingInput(f"{what} {path!r} is not a folder that exists; check the path")
    if not folder and not found.is_file():
        raise MissingInput(f"{what} {path!r} is not a file that exists; check the path")
    return found


def parse_size(_ctx, _param, value: str) -> tuple[int, int]:
    """A click callback: "WIDTHxHEIGHT" in pixels to (width, height), or a one-line usage error."""
    try:
        width, height = (int(part) for part in value.lower().split("x"))
    except ValueError:
        raise click.BadParameter(f"{value!r} is not WIDTHxHEIGHT in pixels, e.g. 1280x720") from None
    return width, height


def per_file(description: str, work):
    """Run ``work(advance)`` under a transient progress bar advanced once per file."""
    with progress_bar(transient=True) as progress:
        task = progress.add_task(description, total=None, last="")
        return work(lambda name: progress.update(task, advance=1, last=name))


def print_summary(summary: dict, as_json: bool, text: str) -> None:
    """The summary as JSON with --json, else its one line of text."""
    if as_json:
        print_json(summary)
    else:
        click.echo(text)


def number_pair(text: str, what: str, kind=int, count: int = 2) -> tuple:
    """``count`` numbers from "7x5" or "0,-60,-10" (an option named ``what``), or a usage error."""
    try:
        parts = tuple(kind(part) for part in text.replace("x", ",").split(","))
    except ValueError:
        parts = ()
    if len(parts) != count:
        raise click.BadParameter(f"{what} {text!r} needs {count} numbers separated by ',' or 'x'")
    return parts
