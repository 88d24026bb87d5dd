"""`vascsim score` and `vascsim report`: metrics and study reports."""

from __future__ import annotations

from pathlib import Path

import click

from sessions.cli.base import (
    analysis_options,
    open_catalog,
    print_json,
    progress_bar,
    stderr_console,
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


def _study_sessions(catalog, study: str, only_unscored: bool = False) -> list[str]:
    """See :meth:`sessions.store.CatalogStore.scorable_sessions`."""
    from sessions.store import CatalogStore

    return CatalogStore(catalog).scorable_sessions(study, only_unscored)


def _score_with_progress(catalog, home, targets, scheduler, workers, data_root=None) -> dict:
    from sessions.scoring import score_sessions

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
    targets = list(uids) + (_study_sessions(catalog, study) if study else [])
    if not targets:
        raise CatalogError("nothing to score: give session ids or --study")
    results = _score_with_progress(catalog, home, targets, scheduler, workers, data_root)
    if as_json:
        print_json(results)
    else:
        click.echo(f"scored {len(results)} session(s)")
    push_after_scoring(catalog, home, results)


@click.command()
@click.option("--study", required=True, help="Study to report on.")
@click.option(
    "--out",
    type=click.Path(file_okay=False),
    default=None,
    help="Folder (default VASCSIM_HOME/reports/STUDY).",
)
@click.option("--groups", default=None, help="Override: the two groups compared, skilled first (a,b).")
@click.option(
    "--level", type=click.Choice(["participant", "trial"]), default=None, help="Override: analysis level."
)
@click.option("--metrics", "metric_names", default=None, help="Override: comma-separated primary metrics.")
@click.option("--rule", default=None, help="Override: benchmark rule, mean, median or percentile:Q.")
@click.option(
    "--rating", default=None, help="Override: a continuous rating for concurrent validity, e.g. grs_total."
)
@click.option("--task", default=None, help="Override: the task whose sessions are analysed.")
@SCHEDULER
@WORKERS
@DATA_ROOT
@click.option("--json", "as_json", is_flag=True, help="Print the validity table as JSON.")
@user_errors
def report(
    study, out, groups, level, metric_names, rule, rating, task, scheduler, workers, data_root, as_json
) -> None:
    """Write a study report (HTML, Markdown, CSV tables, PNG/SVG figures).

    The analysis is the one the study declared (`vascsim studies analysis STUDY` shows it), the
    same the dashboard and the demo use. Options override it for this report only; the report
    says which. With --workers or --scheduler, sessions not yet scored under this metrics
    registry are scored on Dask first (otherwise the report leaves them out and says so).
    """

    from metrics.report import write_report
    from sessions.analysis import analyse_catalog_study

    catalog, home = open_catalog()
    if scheduler or workers or data_root:
        stale = _study_sessions(catalog, study, only_unscored=True)
        if stale:
            _score_with_progress(catalog, home, stale, scheduler, workers, data_root)
    overrides = analysis_options(groups, level, metric_names, rule)
    if rating is not None:
        overrides["rating_col"] = rating
    if task is not None:
        overrides["task"] = task
    with stderr_console().status("analysing and writing the report..."):
        analysis, source = analyse_catalog_study(catalog, study, overrides)
        page = write_report(analysis, Path(out) if out else home / "reports" / study, title=f"Study {study}")
    if as_json:
        print_json(
            {
                "report": str(page),
                "analysis_version": source.version,
                "overridden": {k: {"declared": a, "used": b} for k, (a, b) in source.overridden.items()},
                "validity": analysis.validity.table.to_dict(orient="records"),
                "benchmarks": analysis.benchmarks.to_dict(orient="records"),
                "proficiency": analysis.proficiency.to_dict(orient="records"),
                "concurrent": None
                if analysis.concurrent is None
                else analysis.concurrent.table.to_dict(orient="records"),
                "standard_setting": None
                if analysis.standards is None
                else analysis.standards.misclassification.to_dict(orient="records"),
                "test_retest": None
                if analysis.reliability is None
                else analysis.reliability.test_retest.to_dict(orient="records"),
                "inter_rater": {}
                if analysis.reliability is None
                else {k: v.to_dict(orient="records") for k, v in analysis.reliability.raters.items()},
            }
        )
        return
    for note in analysis.notes[:2]:
        click.echo(note)
    click.echo(f"report: {page}")
