"""`vascsim report`: a study's report (HTML, Markdown, CSV tables, figures) under its declared analysis."""

from __future__ import annotations

from pathlib import Path

import click

from sessions.cli.base import (
    analysis_options,
    open_catalog,
    print_json,
    stderr_console,
    user_errors,
)
from sessions.cli.score import DATA_ROOT, SCHEDULER, WORKERS, score_with_progress, study_sessions


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

    from metrics.reading.report import write_report
    from sessions.scoring.analysis import analyse_catalog_study

    catalog, home = open_catalog()
    if scheduler or workers or data_root:
        stale = study_sessions(catalog, study, only_unscored=True)
        if stale:
            score_with_progress(catalog, home, stale, scheduler, workers, data_root)
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
