"""The study report: HTML and Markdown, CSV tables, PNG and SVG figures, in one folder.

Readable without the dashboard: ``report.html`` embeds nothing remote, the figures
sit beside it, and every choice (label validated against, analysis level, benchmark
rule) is stated in the text. Reports on synthetic participants say so at the top.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd
from jinja2 import Environment

from metrics.reading.study_figures import box_plot_figure, learning_curve_figures, roc_figure
from metrics.reading.tables import (
    FEEDBACK_BASIS,
    benchmarks_for_reading,
    composite_summary,
    composite_weights_for_reading,
    concurrent_for_reading,
    csv_with_units,
    curves_for_reading,
    html_table,
    markdown_table,
    reliability_tables,
    standards_tables,
    trainee_feedback,
    trainee_summary,
    validity_for_reading,
)
from metrics.session.registry import REGISTRY, REGISTRY_VERSION
from metrics.study.analysis import StudyAnalysis
from metrics.study.proficiency import benchmarks_heading

TEMPLATE = Path(__file__).with_name("report.html")
"""The report page (Jinja, autoescaped): every value arrives as text or an already-escaped table."""


def method_lines(analysis: StudyAnalysis) -> list[str]:
    s = analysis.settings
    validity = analysis.validity
    counts = ", ".join(
        f"{g}: {validity.n_participants[g]} participants, {validity.n_sessions[g]} sessions" for g in s.groups
    )
    return [
        f"Label validated against: column '{s.group_col}', {s.groups[0]} vs {s.groups[1]} ({counts}); "
        f"skilled group: {s.skilled_group}.",
        f"Analysis level: {validity.level}"
        + (
            " (one value per participant: the median of their practice sessions)."
            if validity.level == "participant"
            else " (every session a row): a metric discriminates only when the test with group labels "
            "permuted across participants (p_cluster, Holm-corrected) agrees."
        )
        + (
            ""
            if s.baseline_trials is None
            else f" Construct validity compares every {s.skilled_group} practice session with the other "
            f"group's first {s.baseline_trials} practice session(s) each: their baseline, before practice "
            "changed them."
        ),
        "Tests: two-sided Mann-Whitney U (exact permutation p up to 60 values, else normal approximation); "
        "with ties, the exact p is P(|W - E W| >= |w - E W|) over the permutation distribution of the "
        f"midrank sum; Holm correction across {len(validity.table)} metrics at alpha = {s.alpha}; "
        "effect size Cliff's delta (first group minus second).",
        f"AUC = P(a {s.skilled_group} participant does better than the other group's), by each metric's "
        "direction (1 = perfect separation the expected way, 0.5 = none); the raw P(first > second) is "
        "'auc_raw' in construct_validity.csv. 95 % interval: Newcombe's score method (2006, method 5) "
        "with a continuity correction, counted in participants; none is printed where the design cannot "
        "reach p < alpha.",
        "Composite: weighted mean of z-scores, weights = rank-biserial correlation with the skilled group, "
        "all fitted without the left-out participant (leave-one-participant-out).",
        f"Benchmarks: rule '{s.benchmark_rule}' over {s.skilled_group} participants' medians; a session "
        "passes when every benchmarked metric is at least as good"
        + (
            " and no safety event happened (a back-wall catch, a torn wound edge, a force clamped to the "
            "device's rating: non-compensatory mode)"
            if s.non_compensatory
            else ""
        )
        + "; proficient after "
        + (
            f"{s.consecutive_passes} passes in a row."
            if s.progression_window is None
            else f"{s.consecutive_passes} passes among the last {s.progression_window} sessions."
        ),
        "Retention: each trainee's last retention-phase session against the mean of their last "
        f"{s.retention_baseline} practice sessions, per benchmarked metric by its direction; retained "
        "when that session passes the benchmarks.",
        f"Learning curves: {s.learning_model} law per trainee and benchmarked metric; "
        "CUSUM on failed sessions "
        f"with acceptable failure rate {s.cusum_p0} and unacceptable {s.cusum_p1} (alpha = beta = 0.1).",
    ]


def generated_line() -> str:
    """When and by what the report was made: the UTC time, the vascsim version and the metric
    registry version (results of another registry version are not comparable)."""
    from datetime import UTC, datetime
    from importlib.metadata import PackageNotFoundError, version

    try:
        software = version("vascsim")
    except PackageNotFoundError:  # run from a source tree that was never installed
        software = "unknown (not installed)"
    stamp = datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC")
    return f"Generated {stamp} by vascsim {software}, metric registry version {REGISTRY_VERSION}."


def write_report(analysis: StudyAnalysis, folder: str | Path, title: str = "vascsim study report") -> Path:
    """Write the report folder; returns the path of ``report.html`` (``report.md`` sits beside it)."""
    folder = Path(folder)
    figures = folder / "figures"
    tables = folder / "tables"
    figures.mkdir(parents=True, exist_ok=True)
    tables.mkdir(parents=True, exist_ok=True)

    csv = {
        "session_metrics.csv": analysis.sessions,
        "construct_validity.csv": analysis.validity.table,
        "benchmarks.csv": analysis.benchmarks,
        "proficiency.csv": analysis.proficiency,
        "trainees.csv": analysis.trainees,
        "learning_curves.csv": analysis.learning_curves,
        "registry.csv": REGISTRY.describe(),
    }
    concurrent = analysis.concurrent
    if concurrent is not None:
        csv["concurrent_validity.csv"] = concurrent.table
    if analysis.standards is not None:
        csv["standard_setting.csv"] = analysis.standards.misclassification
        csv["rule_comparison.csv"] = analysis.standards.rule_comparison
        if analysis.standards.leave_one_expert_out is not None:
            csv["leave_one_expert_out.csv"] = analysis.standards.leave_one_expert_out
    if analysis.reliability is not None:
        csv["test_retest.csv"] = analysis.reliability.test_retest
        for name, table in analysis.reliability.raters.items():
            csv[f"inter_rater_{name.lower()}.csv"] = table
    if analysis.validity.composite is not None:
        csv["composite_scores.csv"] = analysis.validity.composite.scores
        csv["composite_weights.csv"] = analysis.validity.composite.weights.rename_axis("metric").reset_index()
    for name, frame in csv.items():
        csv_with_units(name, frame).to_csv(tables / name, index=False)

    box_plots = box_plot_figure(analysis, figures)
    roc = roc_figure(analysis, figures)
    learning = learning_curve_figures(analysis, figures)
    composite = analysis.validity.composite
    composite_text = composite_summary(composite)
    weights = composite_weights_for_reading(composite, str(analysis.settings.skilled_group))
    notes = [*analysis.validity.notes[1:], *analysis.notes]
    summary = validity_for_reading(analysis)
    registry = REGISTRY.describe()[["name", "unit", "better", "definition", "reference"]]
    curves = analysis.learning_curves

    generated = generated_line()
    feedback = trainee_feedback(analysis)
    standards = standards_tables(analysis)
    retest, consistency, raters = reliability_tables(analysis)
    context = {
        "standards": (
            {
                "notes": analysis.standards.notes,
                "rule": analysis.settings.benchmark_rule,
                "marks": html_table(standards["marks"]),
                "loo": html_table(standards["loo"]),
                "rules": html_table(standards["rules"]),
            }
            if standards
            else None
        ),
        "reliability": (
            {
                "notes": analysis.reliability.notes,
                "retest": html_table(retest),
                "consistency": consistency,
                "raters": [(name, html_table(table)) for name, table in raters],
            }
            if analysis.reliability is not None
            else None
        ),
        "title": title,
        "generated": generated,
        "synthetic": analysis.synthetic,
        "method": method_lines(analysis),
        "notes": notes,
        "validity_table": html_table(summary),
        "box_plots": box_plots,
        "composite_text": composite_text,
        "composite_table": html_table(weights),
        "concurrent_table": html_table(concurrent_for_reading(concurrent.table))
        if concurrent is not None
        else "",
        "concurrent_notes": concurrent.notes if concurrent is not None else [],
        "roc": roc,
        "benchmark_table": html_table(benchmarks_for_reading(analysis.benchmarks)),
        "benchmark_heading": benchmarks_heading(
            analysis.benchmarks, analysis.settings.min_experts, analysis.standard_label
        ),
        "trainee_table": html_table(trainee_summary(analysis)),
        "left_out_table": html_table(pd.DataFrame(analysis.left_out)) if analysis.left_out else "",
        "feedback": feedback,
        "feedback_basis": FEEDBACK_BASIS,
        "learning": learning,
        "curve_table": html_table(curves_for_reading(curves)),
        "registry_version": REGISTRY_VERSION,
        "registry_table": html_table(registry),
        "csv": list(csv),
    }
    page = Environment(autoescape=True).from_string(TEMPLATE.read_text(encoding="utf-8")).render(**context)
    (folder / "report.html").write_text(page, encoding="utf-8")

    lines = [f"# {title}", "", generated, ""]
    if analysis.synthetic:
        lines += [
            "> **Synthetic data.** Some or all participants are synthetic scripted profiles; "
            "these numbers demonstrate the pipeline and are not evidence about people.",
            "",
        ]
    lines += ["## How this was analysed", "", *[f"- {m}" for m in method_lines(analysis)], ""]
    if notes:
        lines += ["## Read this first", "", *[f"- {n}" for n in notes], ""]
    lines += ["## Construct validity", "", markdown_table(summary), "", f"![box plots]({box_plots})", ""]
    lines += [
        "## Composite skill score",
        "",
        composite_text,
        "",
        markdown_table(weights),
        "",
        f"![ROC]({roc})",
        "",
    ]
    if concurrent is not None:
        lines += ["## Concurrent validity", "", *[f"- {n}" for n in concurrent.notes], ""]
        lines += [markdown_table(concurrent_for_reading(concurrent.table)), ""]
    benchmarks = markdown_table(benchmarks_for_reading(analysis.benchmarks))
    heading = benchmarks_heading(analysis.benchmarks, analysis.settings.min_experts, analysis.standard_label)
    lines += [
        f"## {heading}",
        "",
        benchmarks,
        "",
    ]
    if standards:
        lines += ["## Standard setting: how often each pass mark misjudges", ""]
        lines += [*[f"- {n}" for n in analysis.standards.notes], "", markdown_table(standards["marks"]), ""]
        lines += [f"### Leaving one expert out (rule '{analysis.settings.benchmark_rule}')", ""]
        lines += [markdown_table(standards["loo"]), "", "### What each rule does to the course", ""]
        lines += [markdown_table(standards["rules"]), ""]
    if analysis.reliability is not None:
        lines += ["## Reliability", "", *[f"- {n}" for n in analysis.reliability.notes], ""]
        lines += ["### Test-retest (benchmarked metrics)", "", markdown_table(retest), "", consistency, ""]
        for name, table in raters:
            lines += [f"### Inter-rater agreement: {name}", "", markdown_table(table), ""]
    lines += ["## Trainees", "", markdown_table(trainee_summary(analysis)), ""]
    if feedback:
        lines += ["### What each trainee should work on next", "", FEEDBACK_BASIS, ""]
        for code, items in feedback:
            lines += [f"#### {code}", ""]
            lines += [f"{n}. **{i['kind']}**: {i['line']}" for n, i in enumerate(items["work_on"], start=1)]
            lines += [] if items["work_on"] else ["Nothing worse than the experts' middle half."]
            lines += ["", *[f"- Strength: {i['line']}" for i in items["strengths"]], ""]
    if analysis.left_out:
        lines += ["### Participants not in this analysis, and why", ""]
        lines += [markdown_table(pd.DataFrame(analysis.left_out)), ""]
    lines += [f"![learning curve]({p})" for p in learning] + [""]
    lines += ["## Learning-curve fits", "", markdown_table(curves_for_reading(curves)), ""]
    lines += [
        f"## Metric definitions (registry version {REGISTRY_VERSION})",
        "",
        markdown_table(registry),
        "",
    ]
    (folder / "report.md").write_text("\n".join(lines), encoding="utf-8")
    return folder / "report.html"
