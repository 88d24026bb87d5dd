"""`vascsim score`: (re)compute the metrics of sessions or of a whole study, here or on Dask."""

from __future__ import annotations

import click

from sessions.cli.base import (
    open_catalog,
    print_json,
    progress_bar,
    user_errors,
)
from sessions.cli.lrs import push_after_scoring

SCHEDULER = click.option(
    "--scheduler",
    default=None,
    help="Compute on a running Dask cluster (tcp://HOST:8786); sessions must be on a path its workers see.",
)
DATA_ROOT = click.option(
    "--data-root",
    default=None,
    help="Where the workers read sessions from instead of VASCSIM_HOME: a path they mount or an fsspec "
    "URL (s3://..., file://...) holding the same sessions/ folder.",
)
WORKERS = click.option(
    "--workers",
    type=click.IntRange(1, 256),
    default=None,
    help="Compute on a local Dask cluster of N worker processes.",
)


def study_sessions(catalog, study: str, only_unscored: bool = False) -> list[str]:
    """See :meth:`sessions.catalog.store.CatalogStore.scorable_sessions`."""
    from sessions.catalog.store import CatalogStore

    return CatalogStore(catalog).scorable_sessions(study, only_unscored)


def score_with_progress(catalog, home, targets, scheduler, workers, data_root=None) -> dict:
    from sessions.scoring.workers import score_sessions

    where = f" on {scheduler}" if scheduler else (f" on {workers} local Dask workers" if workers else "")
    with progress_bar() as progress:
        task = progress.add_task(f"scoring{where}", total=len(targets), last="")
        return score_sessions(
            catalog,
            targets,
            home,
            scheduler=scheduler,
            workers=workers,
            progress=lambda uid: progress.update(task, advance=1, last=uid),
            data_root=data_root,
        )


@click.command()
@click.argument("uids", nargs=-1)
@click.option("--study", default=None, help="Score every complete session of this study.")
@SCHEDULER
@WORKERS
@DATA_ROOT
@click.option("--json", "as_json", is_flag=True, help="Print the metrics as JSON.")
@user_errors
def score(uids, study, scheduler, workers, data_root, as_json) -> None:
    """(Re)compute every metric of the given sessions, or of a whole study (in this process, or on
    Dask with --workers N or --scheduler tcp://HOST:8786: the same results)."""
    from sessions.catalog import CatalogError

    catalog, home = open_catalog()
    targets = list(uids) + (study_sessions(catalog, study) if study else [])
    if not targets:
        raise CatalogError("nothing to score: give session ids or --study")
    results = score_with_progress(catalog, home, targets, scheduler, workers, data_root)
    if as_json:
        print_json(results)
    else:
        click.echo(f"scored {len(results)} session(s)")
    push_after_scoring(catalog, home, results)
