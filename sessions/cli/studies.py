"""`vascsim studies ...`: studies and their declared analysis."""

from __future__ import annotations

import click
import pandas as pd

from sessions.cli.base import (
    analysis_options,
    open_catalog,
    open_store,
    print_frame,
    print_json,
    user_errors,
)


@click.group()
def studies() -> None:
    """Studies and courses in the catalog."""


@studies.command("list")
@click.option("--json", "as_json", is_flag=True, help="Print as JSON.")
@user_errors
def studies_list(as_json: bool) -> None:
    """List studies with their participant and session counts."""

    store, _ = open_store()
    rows = [
        {
            "study": s.name,
            "participants": s.participants,
            "sessions": s.sessions,
            "synthetic": s.synthetic,
            "description": s.description,
        }
        for s in store.studies()
    ]
    if as_json:
        print_json(rows)
        return
    print_frame(
        pd.DataFrame(rows, columns=["study", "participants", "sessions", "synthetic", "description"]),
        "Studies",
    )


@studies.command("add")
@click.argument("name")
@click.option("--description", default="", help="Free text shown in listings and reports.")
@user_errors
def studies_add(name: str, description: str) -> None:
    """Create a study (or course) called NAME."""
    store, _ = open_store()
    store.create_study(name, description)
    click.echo(f"study {name} created")


@studies.command("groups")
@click.argument("study")
@click.option("--add", "added", multiple=True, help="Declare another group (repeatable), e.g. --add fellow.")
@user_errors
def studies_groups(study: str, added: tuple[str, ...]) -> None:
    """List the groups a participant of STUDY can be in, or declare more.

    Every study knows expert, intermediate, trainee and novice; labels are case-insensitive and
    stored lower-case. A label outside the list is refused, so a typo never makes a group nobody
    analyses."""
    from sessions.catalog.groups import STANDARD_GROUPS, study_groups

    catalog, _ = open_catalog()
    groups = study_groups(catalog, study, added)
    custom = [g for g in groups if g not in STANDARD_GROUPS]
    click.echo(
        f"study {study!r}: groups {', '.join(STANDARD_GROUPS)}"
        + (f"; declared: {', '.join(custom)}" if custom else "")
    )


@studies.command("analysis")
@click.argument("study")
@click.option("--groups", default=None, help="The two groups compared, skilled first (a,b).")
@click.option("--level", type=click.Choice(["participant", "trial"]), default=None, help="Analysis level.")
@click.option("--metrics", "metric_names", default=None, help="Comma-separated primary metrics.")
@click.option("--rule", default=None, help="Benchmark rule: mean, median or percentile:Q.")
@click.option(
    "--consecutive", type=int, default=None, help="Consecutive passes that make a trainee proficient."
)
@click.option("--rating", default=None, help="Continuous rating for concurrent validity, e.g. grs_total.")
@click.option(
    "--retention-baseline",
    type=int,
    default=None,
    help="Retention: compare the delayed session with the mean of this many last practice sessions.",
)
@click.option(
    "--baseline-trials",
    type=click.IntRange(0, 1000),
    default=None,
    help="Construct validity compares the skilled group with each other participant's first N practice "
    "sessions (their baseline, before practice); 0 compares every practice session (the default).",
)
@click.option(
    "--benchmarks",
    "benchmark_names",
    default=None,
    help="Comma-separated metrics to set pass marks on (default: the analysed metrics that discriminate). "
    "Only metrics on which the skilled group does better are ever benchmarked.",
)
@click.option(
    "--override-reason",
    default=None,
    help="Why the declared --benchmarks stand though their AUC interval includes 0.5 (printed in every "
    "report); without it such a metric is not benchmarked.",
)
@click.option(
    "--min-experts",
    type=click.IntRange(1, 1000),
    default=None,
    help="Experts a standard needs; fewer make it provisional wherever it is shown [default: 5].",
)
@click.option("--by", "author", default=None, help="Who declares this version (default: the login name).")
@click.option("--note", default="", help="Why this version.")
@click.option("--json", "as_json", is_flag=True, help="Print as JSON.")
@user_errors
def studies_analysis(
    study,
    groups,
    level,
    metric_names,
    rule,
    consecutive,
    rating,
    retention_baseline,
    baseline_trials,
    benchmark_names,
    override_reason,
    min_experts,
    author,
    note,
    as_json,
) -> None:
    """Show a study's declared analysis and its versions, or declare a new version.

    With no option it prints what every report, the dashboard and exports use. Any option
    declares a new version from the current one with that choice changed (recorded with who,
    when and --note); earlier versions are kept.
    """
    import dataclasses
    import getpass

    from sessions.scoring.analysis import (
        DEFAULT_WORDS,
        analysis_history,
        declare_analysis,
        declared_settings,
        settings_to_json,
    )

    catalog, _ = open_catalog()
    changes = analysis_options(groups, level, metric_names, rule, consecutive)
    if rating is not None:
        changes["rating_col"] = rating
    if retention_baseline is not None:
        changes["retention_baseline"] = retention_baseline
    if baseline_trials is not None:
        changes["baseline_trials"] = baseline_trials or None
    if benchmark_names is not None:
        changes["benchmark_metrics"] = tuple(p.strip() for p in benchmark_names.split(",") if p.strip())
    if override_reason is not None:
        changes["benchmark_override"] = override_reason.strip()
    if min_experts is not None:
        changes["min_experts"] = min_experts
    if changes:
        current, _, _ = declared_settings(catalog, study)
        version = declare_analysis(
            catalog, study, dataclasses.replace(current, **changes), author or getpass.getuser(), note
        )
        click.echo(f"study {study!r}: analysis version {version} declared")
    settings, version, who = declared_settings(catalog, study)
    history = analysis_history(catalog, study)
    if as_json:
        print_json(
            {"study": study, "version": version, "settings": settings_to_json(settings), "history": history}
        )
        return
    click.echo(
        f"study {study!r}: "
        + (f"declared analysis version {version} (by {who})" if version else "no analysis declared; defaults")
    )
    for name, value in settings_to_json(settings).items():
        if value is None:
            value = f"default: {DEFAULT_WORDS[name]}"
        elif value == "":
            value = "none"
        elif isinstance(value, list):
            value = ", ".join(value)
        line = f"{name:20s} {value}"
        click.echo(click.wrap_text(line, 80, initial_indent="  ", subsequent_indent=" " * 23))
    for entry in history:
        click.echo(f"  v{entry['version']} {entry['created_at']} {entry['author']}: {entry['note']}")
