"""`vascsim demo`: the synthetic course end to end."""

from __future__ import annotations

import click

from sessions.cli.base import (
    open_catalog,
    print_frame,
    print_json,
    progress_bar,
    user_errors,
)
from sessions.cli.sessions import final_task_line


def proficiency_rule(analysis) -> str:
    """The rule the proficiency table applies, and what retention compares, in one caption."""
    settings = analysis.settings
    benchmarked = ", ".join(analysis.benchmarks["metric"]) if len(analysis.benchmarks) else "none"
    return (
        f"Proficient: {settings.consecutive_passes} practice sessions in a row that pass every benchmark "
        f"(rule {settings.benchmark_rule} of the experts' medians; benchmarked: {benchmarked}). Retention: "
        "the delayed session passes every benchmark too; a trainee who has not reached them in practice "
        "cannot keep them."
    )


@click.command()
@click.option(
    "--small",
    is_flag=True,
    help="A reduced study (2 experts x 2, 3 trainees x 3 + retention) for a quick look: too small to "
    "set a standard or show learning.",
)
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
@user_errors
def demo(small: bool, as_json: bool) -> None:
    """Run a small synthetic study end to end and print what it found.

    With no hardware and no configuration, a two-task course on a porcine artery
    with an arteriotomy: 5 synthetic experts x 2 sessions and 6 synthetic trainees
    x 8 practice sessions + 1 retention session of the interrupted stitch (the
    sixth a slow learner), then every participant closes the arteriotomy once (a
    row of three stitches). Each session is a scripted pass through the real
    simulator (simulated time, two at once), recorded, catalogued and scored.
    Then it prints which metrics discriminate on the practice task (primary set
    declared in advance; experts against each trainee's first two sessions),
    effect sizes, the standard it set from the experts, each trainee's
    proficiency status, the final task's largest differences, and the paths of
    the reports (HTML, Markdown, CSV, figures). Under 120 s on 2 cores.
    Re-running replaces the previous demo study; participants are labelled
    synthetic everywhere.
    """
    from metrics.reading.tables import compact_caption, compact_summary, composite_summary, summary_table
    from sessions.catalog.store import CatalogStore
    from sessions.demo import DEMO_STUDY, DemoSize, run_demo

    catalog, home = open_catalog()
    size = DemoSize(2, 2, 3, 3, True) if small else DemoSize()
    with progress_bar() as progress:
        task = progress.add_task("synthetic sessions", total=size.sessions, last="")
        result = run_demo(
            catalog, home, size, advance=lambda text: progress.update(task, advance=1, last=text)
        )
    analysis = result.analysis
    validity = analysis.validity
    groups = analysis.settings.groups
    summary = compact_summary(analysis)
    trainees = analysis.trainees[["participant_id", "passes", "proficient", "trials_to_proficiency"]].copy()
    if "retention_passed" in analysis.trainees:
        trainees["retention_passed"] = analysis.trainees["retention_passed"]
    if as_json:
        print_json(
            {
                "sessions": result.sessions,
                "seconds": result.seconds,
                "report": str(result.report),
                "metrics": summary_table(analysis).to_dict(orient="records"),
                "trainees": trainees.to_dict(orient="records"),
                "notes": validity.notes + analysis.notes,
                "composite_auc": None if validity.composite is None else validity.composite.auc,
                "composite": composite_summary(validity.composite),
                "synthetic": True,
                "relinked": list(result.relinked),
                "unlinked": list(result.unlinked),
                "videos_removed": result.videos_removed,
            }
        )
        return
    print_frame(
        summary,
        f"Construct validity, {groups[0]} vs {groups[1]}, participant level (SYNTHETIC participants)",
        compact_caption(analysis),
    )
    shown = trainees.rename(
        columns={
            "participant_id": "trainee",
            "trials_to_proficiency": "proficient at trial",
            "retention_passed": "retention passed",
        }
    )
    if analysis.benchmarks.empty:  # no standard: nobody passed or failed a mark that does not exist
        shown = shown[["trainee"]].assign(proficient="no standard")
    heading = analysis.standard_label or "benchmarks from the experts"
    print_frame(shown, f"Trainees: proficiency ({heading})", proficiency_rule(analysis))
    for note in validity.notes + analysis.notes:
        click.echo(click.wrap_text(f"note: {note}", 80, subsequent_indent="      "))
    click.echo(f"composite score: {composite_summary(validity.composite)}")
    if result.final is not None:
        click.echo(final_task_line(result.final, result.final_report))
    click.echo(f"{result.sessions} sessions in {result.seconds:.0f} s; full report: {result.report}")
    for line in rerun_lines(result):
        click.echo(click.wrap_text(line, 80, subsequent_indent="  "))
    first_trainee = analysis.sessions.loc[analysis.sessions["label"] == "trainee", "session_id"]
    if len(first_trainee):
        click.echo(
            f"replay a trainee against the experts: vascsim replay {first_trainee.iloc[0]} "
            "--vs-group experts --mode side-by-side"
        )
    study_id = CatalogStore(catalog).study_named(DEMO_STUDY).id
    click.echo(
        "open the results in the dashboard: vascsim users add NAME --role admin; vascsim serve; "
        f"then http://127.0.0.1:8000/studies/{study_id}"
    )
    click.echo(
        f"try a stitch yourself (on a display; keyboard and mouse): vascsim participants add ME --study "
        f"{DEMO_STUDY} --level trainee; vascsim station --study {DEMO_STUDY} --participant ME --device mouse"
    )


def rerun_lines(result) -> list[str]:
    """What a re-run did to what the previous demo left: accounts linked again, accounts whose
    participant the new demo has no more, replay videos removed with their sessions."""
    lines = []
    if result.relinked:
        lines.append(f"trainee accounts linked again to the new demo's {', '.join(result.relinked)}")
    if result.unlinked:
        lines.append(
            f"accounts of {', '.join(result.unlinked)} are no longer linked: this demo has no such "
            "participant (link them on the Administration page)"
        )
    if result.videos_removed:
        lines.append(f"removed {result.videos_removed} replay video(s) of the previous demo's sessions")
    return lines
