"""The study report: HTML and Markdown, CSV tables, PNG and SVG figures, in one folder.

Readable without the dashboard: ``report.html`` embeds nothing remote, the figures
sit beside it, and every choice (label validated against, analysis level, benchmark
rule) is stated in the text. Reports on synthetic participants say so at the top.
"""

from __future__ import annotations

import html
import math
from pathlib import Path

import numpy as np
import pandas as pd
from jinja2 import Environment
from markupsafe import Markup
from matplotlib.ticker import MaxNLocator
from sklearn.metrics import roc_curve

from metrics.feedback import RECENT_SESSIONS, participant_feedback
from metrics.figures import new_figure
from metrics.learning import MODELS as LEARNING_MODELS
from metrics.proficiency import benchmarks_heading
from metrics.registry import REGISTRY, REGISTRY_VERSION, display_name
from metrics.reliability import agreement_shown
from metrics.study import StudyAnalysis, metric_unit, oriented, practice_mask
from metrics.units import display_unit, in_display_units, interval_text, significant
from metrics.validity import aggregate_by_participant

FIGURE_FORMATS = ("png", "svg")


def _save(figure, folder: Path, name: str) -> str:
    for kind in FIGURE_FORMATS:
        figure.savefig(folder / f"{name}.{kind}", dpi=100)
    return f"figures/{name}.png"


def participant_medians(analysis: StudyAnalysis, metrics: list[str]) -> pd.DataFrame:
    """One row per participant of the compared groups: the median of their practice sessions."""
    settings = analysis.settings
    data = analysis.sessions
    compared = data[practice_mask(data) & data[settings.group_col].isin(settings.groups)]
    return aggregate_by_participant(compared, settings.group_col, settings.cluster_col, metrics)


def display_scale(metric: str) -> tuple[float, str]:
    """The factor from SI to the unit a surgeon reads, and that unit's axis label with the direction."""
    unit = metric_unit(metric)
    better = REGISTRY[metric].better if metric in REGISTRY else ""
    shown = display_unit(unit)
    label = f"{shown}, {better} is better" if shown else f"{better} is better"
    return float(in_display_units(1.0, unit) or 1.0), label


def _box_plots(analysis: StudyAnalysis, folder: Path) -> str:
    settings = analysis.settings
    metrics = analysis.validity.table["metric"].tolist()
    columns = 4
    rows = max(1, math.ceil(len(metrics) / columns))
    figure = new_figure(figsize=(3.2 * columns, 2.6 * rows))
    axes = figure.subplots(rows, columns, squeeze=False)
    per_participant = participant_medians(analysis, metrics)
    significant = set(analysis.validity.discriminating())
    for axis, metric in zip(axes.ravel(), metrics, strict=False):
        factor, label = display_scale(metric)
        groups = [
            factor * per_participant.loc[per_participant[settings.group_col] == g, metric].dropna()
            for g in settings.groups
        ]
        axis.boxplot(groups, tick_labels=list(settings.groups), widths=0.5)
        for k, values in enumerate(groups, start=1):
            axis.scatter(
                np.full(len(values), k) + np.linspace(-0.08, 0.08, len(values)), values, s=8, alpha=0.6
            )
        axis.set_title(metric + (" *" if metric in significant else ""), fontsize=9)
        axis.set_ylabel(label, fontsize=8)
        axis.tick_params(labelsize=7)
    for axis in axes.ravel()[len(metrics) :]:
        axis.set_visible(False)
    figure.suptitle(
        f"Per-participant medians by {settings.group_col} (* discriminates after Holm)", fontsize=10
    )
    figure.tight_layout()
    return _save(figure, folder, "box_plots")


def _roc(analysis: StudyAnalysis, folder: Path) -> str:
    settings = analysis.settings
    table = analysis.validity.table.dropna(subset=["auc"])
    ranked = table.assign(effect=(table["auc"] - 0.5).abs()).sort_values("effect", ascending=False).head(6)
    per_participant = participant_medians(analysis, ranked["metric"].tolist())
    skilled = (per_participant[settings.group_col] == settings.skilled_group).to_numpy()
    figure = new_figure(figsize=(5, 5))
    axis = figure.subplots()
    for metric in ranked["metric"]:
        values = oriented(per_participant[metric], metric)
        keep = ~np.isnan(values)
        if keep.sum() < 2 or len(set(skilled[keep])) < 2:
            continue
        fpr, tpr, _ = roc_curve(skilled[keep], values[keep])
        area = float(np.trapezoid(tpr, fpr))
        axis.plot(fpr, tpr, label=f"{metric} (AUC {area:.2f})")
    composite = analysis.validity.composite
    if composite is not None and not math.isnan(composite.auc):
        scores = composite.scores.dropna(subset=["score"])
        fpr, tpr, _ = roc_curve(scores["group"] == settings.skilled_group, scores["score"])
        axis.plot(fpr, tpr, "k", linewidth=2.5, label=f"composite, out of fold (AUC {composite.auc:.2f})")
    axis.plot([0, 1], [0, 1], ":", color="grey")
    axis.set_xlabel("false positive rate")
    axis.set_ylabel(f"true positive rate ({settings.skilled_group})")
    axis.set_title("ROC, participant level, metrics oriented better = higher", fontsize=9)
    if axis.get_legend_handles_labels()[1]:
        axis.legend(fontsize=7, loc="lower right")
    else:  # e.g. every expert's or every trainee's sessions unscored: say so rather than draw nothing
        axis.text(0.5, 0.5, "no curve: no metric has values\nfrom both groups", ha="center", va="center")
    figure.tight_layout()
    return _save(figure, folder, "roc")


MAX_LEARNING_PANELS = 8
MAX_TRAINEES_DRAWN = 24


def _learning_curves(analysis: StudyAnalysis, folder: Path) -> list[str]:
    """A panel per benchmarked metric (up to 8): trainees' trials, fitted curves, retention, benchmark."""
    settings = analysis.settings
    data = analysis.sessions
    practice = practice_mask(data)
    trainees = data[
        (data[settings.group_col] != settings.skilled_group) & data[settings.group_col].isin(settings.groups)
    ]
    benchmarks = list(analysis.benchmarks.itertuples())[:MAX_LEARNING_PANELS]
    if not benchmarks or trainees.empty:
        return []
    columns = min(2, len(benchmarks))
    rows = math.ceil(len(benchmarks) / columns)
    figure = new_figure(figsize=(6 * columns, 3.4 * rows))
    axes = figure.subplots(rows, columns, squeeze=False)
    curves = analysis.learning_curves
    fitted = {(r.participant_id, r.metric): r for r in curves.itertuples()} if not curves.empty else {}
    participants = trainees[settings.cluster_col].unique()[:MAX_TRAINEES_DRAWN]
    for axis, bench in zip(axes.ravel(), benchmarks, strict=False):
        factor, label = display_scale(bench.metric)
        for participant in participants:
            mine = trainees[trainees[settings.cluster_col] == participant]
            done = mine[practice.loc[mine.index]]
            line = axis.plot(done["trial"], factor * done[bench.metric], "o", markersize=3, alpha=0.7)
            colour = line[0].get_color()
            fit = fitted.get((participant, bench.metric))
            end = (done["trial"].iloc[-1], factor * done[bench.metric].iloc[-1]) if len(done) else None
            if fit is not None:
                n = np.linspace(1, done["trial"].max(), 60)
                fitted_values = factor * LEARNING_MODELS[fit.model](n, fit.plateau, fit.amplitude, fit.rate)
                axis.plot(n, fitted_values, "-", color=colour, alpha=0.7, linewidth=1)
                end = (n[-1], fitted_values[-1])
            if end is not None and np.isfinite(end[1]):  # each trainee's curve carries its code
                axis.annotate(
                    str(participant),
                    end,
                    xytext=(3, 0),
                    textcoords="offset points",
                    fontsize=6,
                    color=colour,
                    va="center",
                )
            delayed = mine[~practice.loc[mine.index]]
            axis.plot(delayed["trial"], factor * delayed[bench.metric], "s", color=colour, markersize=5)
        axis.axhline(factor * bench.benchmark, color="k", linestyle="--", label=f"benchmark ({bench.rule})")
        axis.set_xlabel("trial (squares: retention)", fontsize=8)
        axis.xaxis.set_major_locator(MaxNLocator(integer=True))  # trials are whole sessions
        axis.set_ylabel(f"{bench.metric} ({label})", fontsize=8)
        axis.set_title(f"{bench.metric} ({bench.better} is better)", fontsize=9)
        axis.legend(fontsize=7)
    for axis in axes.ravel()[len(benchmarks) :]:
        axis.set_visible(False)
    figure.tight_layout()
    return [_save(figure, folder, "learning_curves")]


def table_text(value) -> str:
    if value is None or value is pd.NA or (isinstance(value, float) and math.isnan(value)):
        return ""
    if isinstance(value, bool | np.bool_):
        return "yes" if value else "no"
    if isinstance(value, float | np.floating):
        return significant(float(value))
    return str(value)


def _markdown_table(frame: pd.DataFrame) -> str:
    header = "| " + " | ".join(map(str, frame.columns)) + " |"
    rule = "| " + " | ".join("---" for _ in frame.columns) + " |"
    body = ["| " + " | ".join(table_text(v) for v in row) + " |" for row in frame.itertuples(index=False)]
    return "\n".join([header, rule, *body])


def _html_table(frame: pd.DataFrame) -> Markup:
    """Numbers right-aligned, text (names, rules, conditions, yes/no) left-aligned."""
    numeric = [
        pd.api.types.is_numeric_dtype(frame[c]) and not pd.api.types.is_bool_dtype(frame[c]) for c in frame
    ]
    align = ["" if is_number else ' class="text"' for is_number in numeric]
    head = "".join(f"<th{a}>{html.escape(str(c))}</th>" for c, a in zip(frame.columns, align, strict=True))
    body = "".join(
        "<tr>"
        + "".join(f"<td{a}>{html.escape(table_text(v))}</td>" for v, a in zip(row, align, strict=True))
        + "</tr>"
        for row in frame.itertuples(index=False)
    )
    return Markup(f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>")


def trainee_summary(analysis: StudyAnalysis) -> pd.DataFrame:
    """Each trainee in words a supervisor reads: sessions, passes, proficiency, CUSUM, retention; and
    each benchmarked metric's retention change (retention minus practice) in display units, the header
    naming unit and direction. The full table stays in tables/trainees.csv."""
    trainees = analysis.trainees
    if trainees.empty:
        return trainees
    rows = []
    for row in trainees.to_dict(orient="records"):
        trials = row.get("trials_to_proficiency")
        competent = row.get("cusum_competent_at")
        kept = row.get("retention_passed")
        worse = row.get("retention_worse_metrics")
        record = {
            "trainee": row["participant_id"],
            "practice sessions": int(row["practice_sessions"]),
            "at the benchmark": int(row["passes"]),
            "proficient": f"yes, at trial {int(trials)}"
            if bool(row["proficient"]) and not pd.isna(trials)
            else "not yet",
            "CUSUM": f"competent at trial {int(competent)}" if not pd.isna(competent) else "not yet",
            "retention session": "-"
            if kept is None or pd.isna(kept)
            else _retention_words(bool(kept), worse),
        }
        for name in trainees.columns:
            if name.startswith("retention_change_"):
                metric = name[len("retention_change_") :]
                unit = display_unit(metric_unit(metric))
                better = REGISTRY[metric].better if metric in REGISTRY else ""
                header = f"{display_name(metric)} change ({unit + ', ' if unit else ''}{better} is better)"
                record[header] = (
                    in_display_units(row[name], metric_unit(metric)) if not pd.isna(row[name]) else None
                )
        rows.append(record)
    return pd.DataFrame(rows)


FEEDBACK_BASIS = (
    f"Each trainee's last {RECENT_SESSIONS} practice sessions (the median of each metric) against the "
    "experts' middle half on this task: the pass marks missed first, then the never events, safety, the "
    "quality of the stitch and efficiency, each by how far outside the experts' band; the same lines as "
    "the participant page."
)


def trainee_feedback(analysis: StudyAnalysis) -> list[tuple[str, dict]]:
    """Per trainee (as in the trainee table), :func:`metrics.feedback.participant_feedback`."""
    if analysis.trainees.empty:
        return []
    return [(code, participant_feedback(analysis, code)) for code in analysis.trainees["participant_id"]]


def _retention_words(at_benchmark: bool, worse: float | None) -> str:
    """ "worse than the benchmark; worse than practice on 1 metric(s)": the session against the benchmark,
    then against the trainee's own practice (the study's retention rule)."""
    text = "at the benchmark" if at_benchmark else "worse than the benchmark"
    if worse is None or pd.isna(worse):
        return text
    count = int(worse)
    return text + (
        "; no metric worse than practice" if count == 0 else f"; worse than practice on {count} metric(s)"
    )


def summary_table(analysis: StudyAnalysis) -> pd.DataFrame:
    """The validity table's headline columns, in the order a reader scans them."""
    groups = analysis.settings.groups
    table = analysis.validity.table
    columns = [
        "metric",
        "unit",
        "better",
        f"median_{groups[0]}",
        f"median_{groups[1]}",
        "auc",
        "auc_ci_low",
        "auc_ci_high",
        "cliffs_delta",
        "p_value",
    ]
    if analysis.validity.level == "trial":
        columns += ["p_cluster"]
    columns += ["p_holm", "discriminates", "direction", "as_expected"]
    return table[columns]


def summary_in_display_units(analysis: StudyAnalysis) -> pd.DataFrame:
    """:func:`summary_table` with each group's median in the units a surgeon reads and ``unit`` naming
    that unit ("1" for a count or ratio): what the report and the dashboard show."""
    table = summary_table(analysis).copy()
    units = table["unit"].tolist()
    for group in analysis.settings.groups:
        column = f"median_{group}"
        table[column] = [
            in_display_units(v, u) if v == v else v for v, u in zip(table[column], units, strict=True)
        ]
    table["unit"] = [display_unit(u) or "1" for u in units]
    return table


def validity_download(analysis: StudyAnalysis) -> pd.DataFrame:
    """The validity table as a person downloads it: the medians in the units a surgeon reads, the
    unit beside them, and headers that say so (the report's tables/ keep SI, with registry.csv)."""
    return summary_in_display_units(analysis).rename(
        columns={
            **{f"median_{g}": f"median {g} (participant medians, in unit)" for g in analysis.settings.groups},
            "unit": "unit (of the medians)",
            "better": "better (direction of skill)",
            "auc": "AUC (oriented: 1 = the skilled group better)",
            "auc_ci_low": "AUC 95% CI low",
            "auc_ci_high": "AUC 95% CI high",
            "p_value": "p (Mann-Whitney, exact)",
            "p_holm": "p (Holm-adjusted)",
        }
    )


def validity_for_reading(analysis: StudyAnalysis) -> pd.DataFrame:
    """The construct-validity table as the report shows it: metrics named in words, medians in the
    units a surgeon reads, the AUC beside its interval, headers a reader needs no glossary for, and
    narrow enough for a 1366 px screen (the full table, in SI, is tables/construct_validity.csv)."""
    table = summary_in_display_units(analysis)
    groups = [str(g) for g in analysis.settings.groups]
    shown = pd.DataFrame(
        {
            "metric": [display_name(m) for m in table["metric"]],
            "unit": table["unit"],
            "better": table["better"],
            **{f"{g} median": table[f"median_{g}"] for g in groups},
            "AUC": table["auc"],
            "AUC 95% CI": [
                ("" if a != a else NO_INTERVAL) if low != low else f"{low:.2f}-{high:.2f}"
                for a, low, high in table[["auc", "auc_ci_low", "auc_ci_high"]].to_numpy()
            ],
            "Cliff's delta": table["cliffs_delta"],
            "p": table["p_value"],
            "Holm p": table["p_holm"],
            "discriminates": table["discriminates"],
        }
    )
    if "as_expected" in table.columns:
        shown["as expected"] = table["as_expected"]
    return shown


NO_INTERVAL = "n/a"
"""What an AUC without an interval carries: the design is too small for one (the notes say why)."""


def compact_summary(analysis: StudyAnalysis) -> pd.DataFrame:
    """The headline table for a terminal: direction, medians, oriented AUC with its interval, Holm p, flag
    (read with :func:`compact_caption`)."""
    groups = analysis.settings.groups
    table = summary_table(analysis)
    units = table["unit"].tolist()

    def medians(group: str) -> list[str]:  # in the units a surgeon reads (metrics.units)
        values = table[f"median_{group}"].tolist()
        return [_short(in_display_units(v, u) if v == v else v) for v, u in zip(values, units, strict=True)]

    arrows = {"lower": " \u2193", "higher": " \u2191"}  # down: lower is better, up: higher is
    return pd.DataFrame(
        {
            "metric": table["metric"],
            "unit": [
                (display_unit(u) + arrows.get(b, "")).strip()
                for u, b in zip(units, table["better"], strict=True)
            ],
            str(groups[0]): medians(str(groups[0])),
            str(groups[1]): medians(str(groups[1])),
            "AUC": ["" if a != a else f"{a:.2f}" for a in table["auc"]],
            "95% CI": [
                ("" if a != a else NO_INTERVAL) if low != low else f"{low:.2f}-{high:.2f}"
                for a, low, high in table[["auc", "auc_ci_low", "auc_ci_high"]].to_numpy()
            ],
            "Holm p": [_short(v) for v in table["p_holm"]],
            "flag": table["discriminates"],
        }
    )


def _short(value: float | None) -> str:
    return "" if value is None or value != value else significant(value)


def compact_caption(analysis: StudyAnalysis) -> str:
    skilled = analysis.settings.skilled_group
    groups = " and ".join(map(str, analysis.settings.groups))
    return (
        f"{groups}: participant medians; \u2193 lower is better, \u2191 higher is better. AUC: probability "
        f"that {'an' if skilled[:1] in 'aeiou' else 'a'} {skilled} participant does better (1 = perfect, "
        f"0.5 = none); {NO_INTERVAL}: too few participants for an interval. flag: discriminates after Holm."
    )


def composite_summary(composite) -> str:
    """The composite's out-of-fold AUC, its interval (or why there is none) and what chance alone gives.

    One sentence, the same in the report, the CLI and the dashboard.
    """
    if composite is None:
        return "Too few participants for leave-one-participant-out validation of the composite score."
    if math.isnan(composite.auc):
        return "The composite score could not be validated: a fold lacked one of the groups."
    low, high = composite.auc_ci
    interval = (
        "too few participants for an interval" if math.isnan(low) else f"95 % CI {low:.2f} to {high:.2f}"
    )
    text = (
        f"Out-of-fold AUC {composite.auc:.2f} ({interval}) over {composite.folds} participants, each scored "
        "by a model fitted without them"
    )
    if composite.permutations:
        text += (
            f"; with the group labels permuted across participants the same procedure reaches "
            f"{composite.null_p95:.2f} (95th percentile of {composite.permutations} relabellings), "
            f"p = {composite.null_p:.3g}"
        )
    return text + "."


TEMPLATE = """<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>{{ title }}</title>
<style>
body { font-family: system-ui, sans-serif; max-width: 1100px; margin: 2em auto; color: #222; }
table { border-collapse: collapse; font-size: 0.85em; margin: 1em 0; }
table { display: block; overflow-x: auto; max-width: 100%; } /* a wide table scrolls, the page does not */
th, td { border: 1px solid #ccc; padding: 0.25em 0.5em; text-align: right; }
th { background: #f3f3f3; } td:first-child, th:first-child, td.text, th.text { text-align: left; }
.warning { background: #fff3cd; border: 1px solid #e0c060; padding: 0.6em 1em; }
img { max-width: 100%; }
</style></head><body>
<h1>{{ title }}</h1>
<p class="generated">{{ generated }}</p>
{% if synthetic %}<p class="warning"><strong>Synthetic data.</strong> Some or all participants in this
study are synthetic (scripted profiles run through the simulator), labelled so in the catalog. These numbers
demonstrate the pipeline; they are not evidence about people.</p>{% endif %}
<h2>How this was analysed</h2>
<ul>{% for line in method %}<li>{{ line }}</li>{% endfor %}</ul>
{% if notes %}<h2>Read this first</h2>
<ul>{% for note in notes %}<li class="warning">{{ note }}</li>{% endfor %}</ul>{% endif %}
<h2>Construct validity</h2>
{{ validity_table }}
<p><img src="{{ box_plots }}" alt="box plots per group"></p>
<h2>Composite skill score</h2>
<p>{{ composite_text }}</p>
{{ composite_table }}
<p><img src="{{ roc }}" alt="ROC curves"></p>
{% if concurrent_table %}<h2>Concurrent validity</h2>
<ul>{% for note in concurrent_notes %}<li>{{ note }}</li>{% endfor %}</ul>
{{ concurrent_table }}{% endif %}
<h2>{{ benchmark_heading }}</h2>
{{ benchmark_table }}
{% if standards %}<h2>Standard setting: how often each pass mark misjudges</h2>
<ul>{% for note in standards.notes %}<li>{{ note }}</li>{% endfor %}</ul>
{{ standards.marks }}
<h3>Leaving one expert out (rule '{{ standards.rule }}')</h3>
<p>How many trainees change status (proficient or not) when the benchmarks are set without one expert,
and the largest shift in trials-to-proficiency among those proficient both ways.</p>
{{ standards.loo }}
<h3>What each rule does to the course</h3>
{{ standards.rules }}{% endif %}
{% if reliability %}<h2>Reliability</h2>
<ul>{% for note in reliability.notes %}<li>{{ note }}</li>{% endfor %}</ul>
<h3>Test-retest (benchmarked metrics)</h3>
{{ reliability.retest }}
<p>{{ reliability.consistency }}</p>
{% for name, table in reliability.raters %}<h3>Inter-rater agreement: {{ name }}</h3>
{{ table }}{% endfor %}{% endif %}
<h2>Trainees</h2>
{{ trainee_table }}
{% if feedback %}<h3>What each trainee should work on next</h3>
<p>{{ feedback_basis }}</p>
{% for code, items in feedback %}<h4>{{ code }}</h4>
{% if items.work_on %}<ol class="work-on">{% for item in items.work_on %}
<li><strong>{{ item.kind }}</strong>: {{ item.line }}</li>{% endfor %}</ol>
{% else %}<p>Nothing worse than the experts' middle half.</p>{% endif %}
{% if items.strengths %}<p>Strengths:</p><ul>{% for item in items.strengths %}
<li>{{ item.line }}</li>{% endfor %}</ul>{% endif %}
{% endfor %}{% endif %}
{% if left_out_table %}<h3 id="left-out">Participants not in this analysis, and why</h3>
{{ left_out_table }}{% endif %}
{% for path in learning %}<p><img src="{{ path }}" alt="learning curve"></p>{% endfor %}
<h2>Learning-curve fits</h2>
{{ curve_table }}
<h2>Metric definitions (registry version {{ registry_version }})</h2>
{{ registry_table }}
<p>Tables as CSV (SI units, named in each header or in a unit column):
{% for name in csv %}<a href="tables/{{ name }}">{{ name }}</a> {% endfor %}</p>
</body></html>
"""


def standards_tables(analysis: StudyAnalysis) -> dict[str, pd.DataFrame]:
    """The standard-setting tables as shown: marks in display units, rates in % with intervals."""
    standards = analysis.standards
    if standards is None:
        return {}
    marks = standards.misclassification
    shown = marks[
        ["metric", "rule", "pass_if", "false_pass_shown", "false_fail_shown", "unskilled", "skilled"]
    ].assign(metric=[display_name(m) for m in marks["metric"]])
    shown = shown.rename(
        columns={
            "pass_if": "passes if",
            "false_pass_shown": "false pass (trainees' first session)",
            "false_fail_shown": "false fail (experts)",
            "unskilled": "trainees judged",
            "skilled": "experts judged",
        }
    )
    loo = standards.leave_one_expert_out
    loo = (
        pd.DataFrame()
        if loo is None
        else loo.rename(
            columns={
                "left_out": "expert left out",
                "status_changed": "trainees changing status",
                "changed": "who",
                "largest_shift": "largest shift (sessions)",
                "mean_shift": "mean shift (sessions)",
            }
        )
    )
    rules = standards.rule_comparison.rename(
        columns={"proficient": "trainees proficient", "median_trials": "median trials to proficiency"}
    )
    return {"marks": shown, "loo": loo, "rules": rules}


def reliability_tables(analysis: StudyAnalysis) -> tuple[pd.DataFrame, str, list[tuple[str, pd.DataFrame]]]:
    """(test-retest of the benchmarked metrics, the composite's internal consistency as a sentence,
    inter-rater tables per instrument), as shown."""
    reliability = analysis.reliability
    if reliability is None:
        return pd.DataFrame(), "", []
    chosen = set(analysis.benchmarks["metric"])
    retest = reliability.test_retest[reliability.test_retest["metric"].isin(chosen)]
    retest = pd.DataFrame(
        {
            "metric": [display_name(m) for m in retest["metric"]],
            "participants": retest["participants"],
            "ICC(3,1) (95 % CI), reading": [
                interval_text(v, lo, hi, r)
                for v, lo, hi, r in zip(
                    retest["icc"], retest["ci_low"], retest["ci_high"], retest["reading"], strict=True
                )
            ],
        }
    )
    alpha = reliability.internal_consistency
    if alpha is None:
        consistency = "Internal consistency: needs at least two benchmarked metrics."
    else:
        consistency = (
            "Internal consistency of the benchmarked metrics as one composite (participants' medians, "
            "z-scored, oriented so higher is better): Cronbach's alpha "
            f"{interval_text(alpha.value, alpha.ci_low, alpha.ci_high, alpha.reading)} over {alpha.items} "
            f"metrics and {alpha.subjects} participants."
        )
    raters = [(name, agreement_shown(table)) for name, table in reliability.raters.items()]
    return retest, consistency, raters


def _method_lines(analysis: StudyAnalysis) -> list[str]:
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


def _curves_for_reading(curves: pd.DataFrame) -> pd.DataFrame:
    """The fits as a reader should take them: plateau, amplitude and benchmark in the metric's display
    unit (named in its own column); a plateau the data cannot pin down is not printed."""
    if curves.empty:
        return curves
    shown = curves.drop(columns=["plateau_determined"]).copy()
    units = [metric_unit(m) for m in curves["metric"]]
    shown.insert(shown.columns.get_loc("metric") + 1, "unit", [display_unit(u) for u in units])
    for column in ("plateau", "amplitude", "benchmark"):
        shown[column] = [in_display_units(v, u) for v, u in zip(curves[column], units, strict=True)]
    shown["plateau"] = [
        f"{p:.3g}" if ok and p is not None else "not determined by these trials"
        for p, ok in zip(shown["plateau"], curves["plateau_determined"], strict=True)
    ]
    shown["metric"] = [display_name(m) for m in curves["metric"]]
    return shown.rename(
        columns={
            "participant_id": "trainee",
            "r_squared": "R²",
            "first_observed_at_benchmark": "first trial at the mark",
            "first_predicted_at_benchmark": "trial the fit reaches the mark",
        }
    )


def concurrent_for_reading(table: pd.DataFrame) -> pd.DataFrame:
    """Concurrent validity as a person reads it: per metric, its direction, the participants, Spearman's
    rho with its interval in one cell ("0.65 (-0.08 to 0.98)"), p and Holm p, and whether the metric
    agrees with the rating. Rho is unitless: the metric's unit is not shown (the CSV keeps it)."""
    rows = []
    for row in table.itertuples(index=False):
        low, high = row.rho_ci_low, row.rho_ci_high
        known = low is not None and high is not None and math.isfinite(low) and math.isfinite(high)
        rho = interval_text(row.rho, low, high)
        if not known and math.isfinite(row.rho):
            rho += " (too few participants for an interval)"
        rows.append(
            {
                "metric": display_name(row.metric),
                "better is": row.better,
                "participants": int(row.n),
                "Spearman rho, better with a higher rating (95 % CI)": rho,
                "p": row.p_value,
                "Holm p": row.p_holm,
                "agrees": bool(row.agrees),
            }
        )
    return pd.DataFrame(rows)


def benchmarks_for_reading(benchmarks: pd.DataFrame) -> pd.DataFrame:
    """The benchmarks as a supervisor reads them: each metric's pass condition in its display unit
    ("<= 3.04 deg"), the rule and the experts behind it (the SI mark stays in tables/benchmarks.csv)."""
    if benchmarks.empty:
        return benchmarks
    shown = benchmarks[["metric", "pass_if", "better", "rule", "experts"]]
    shown = shown.assign(metric=[display_name(m) for m in benchmarks["metric"]])
    return shown.rename(columns={"pass_if": "a session passes when", "better": "better is"})


SI_TABLES_IN_METRIC_UNITS = {
    "benchmarks.csv": ("benchmark",),
    "learning_curves.csv": ("plateau", "amplitude", "benchmark"),
}
"""Long tables whose named columns hold values in each row's metric unit: they get a ``unit`` column."""


def csv_with_units(name: str, frame: pd.DataFrame) -> pd.DataFrame:
    """A table as the report writes it to tables/: SI values, and every header says its unit. A wide
    column named after a metric (or ``retention_change_<metric>``) becomes "path_length [m]" (a count
    or ratio, unit "1", keeps its name); a long
    table of :data:`SI_TABLES_IN_METRIC_UNITS` gets a ``unit`` column beside ``metric``."""
    if name in SI_TABLES_IN_METRIC_UNITS and "metric" in frame.columns and "unit" not in frame.columns:
        frame = frame.copy()
        frame.insert(frame.columns.get_loc("metric") + 1, "unit", [metric_unit(m) for m in frame["metric"]])
        return frame

    def header(column: str) -> str:
        metric = column.removeprefix("retention_change_")
        unit = metric_unit(metric) if metric in REGISTRY else ""
        return f"{column} [{unit}]" if unit not in ("", "1") else column  # a count or ratio: no unit

    return frame.rename(columns=header)


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

    box_plots = _box_plots(analysis, figures)
    roc = _roc(analysis, figures)
    learning = _learning_curves(analysis, figures)
    composite = analysis.validity.composite
    composite_text = composite_summary(composite)
    if composite is None:
        weights = pd.DataFrame(columns=["metric", "weight"])
    else:
        weights = composite.weights.rename_axis("metric").reset_index()
        weights = weights[weights["weight"].abs() > 0].sort_values("weight", key=np.abs, ascending=False)
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
                "marks": _html_table(standards["marks"]),
                "loo": _html_table(standards["loo"]),
                "rules": _html_table(standards["rules"]),
            }
            if standards
            else None
        ),
        "reliability": (
            {
                "notes": analysis.reliability.notes,
                "retest": _html_table(retest),
                "consistency": consistency,
                "raters": [(name, _html_table(table)) for name, table in raters],
            }
            if analysis.reliability is not None
            else None
        ),
        "title": title,
        "generated": generated,
        "synthetic": analysis.synthetic,
        "method": _method_lines(analysis),
        "notes": notes,
        "validity_table": _html_table(summary),
        "box_plots": box_plots,
        "composite_text": composite_text,
        "composite_table": _html_table(weights),
        "concurrent_table": _html_table(concurrent_for_reading(concurrent.table))
        if concurrent is not None
        else "",
        "concurrent_notes": concurrent.notes if concurrent is not None else [],
        "roc": roc,
        "benchmark_table": _html_table(benchmarks_for_reading(analysis.benchmarks)),
        "benchmark_heading": benchmarks_heading(
            analysis.benchmarks, analysis.settings.min_experts, analysis.standard_label
        ),
        "trainee_table": _html_table(trainee_summary(analysis)),
        "left_out_table": _html_table(pd.DataFrame(analysis.left_out)) if analysis.left_out else "",
        "feedback": feedback,
        "feedback_basis": FEEDBACK_BASIS,
        "learning": learning,
        "curve_table": _html_table(_curves_for_reading(curves)),
        "registry_version": REGISTRY_VERSION,
        "registry_table": _html_table(registry),
        "csv": list(csv),
    }
    page = Environment(autoescape=True).from_string(TEMPLATE).render(**context)
    (folder / "report.html").write_text(page, encoding="utf-8")

    lines = [f"# {title}", "", generated, ""]
    if analysis.synthetic:
        lines += [
            "> **Synthetic data.** Some or all participants are synthetic scripted profiles; "
            "these numbers demonstrate the pipeline and are not evidence about people.",
            "",
        ]
    lines += ["## How this was analysed", "", *[f"- {m}" for m in _method_lines(analysis)], ""]
    if notes:
        lines += ["## Read this first", "", *[f"- {n}" for n in notes], ""]
    lines += ["## Construct validity", "", _markdown_table(summary), "", f"![box plots]({box_plots})", ""]
    lines += [
        "## Composite skill score",
        "",
        composite_text,
        "",
        _markdown_table(weights),
        "",
        f"![ROC]({roc})",
        "",
    ]
    if concurrent is not None:
        lines += ["## Concurrent validity", "", *[f"- {n}" for n in concurrent.notes], ""]
        lines += [_markdown_table(concurrent_for_reading(concurrent.table)), ""]
    benchmarks = _markdown_table(benchmarks_for_reading(analysis.benchmarks))
    heading = benchmarks_heading(analysis.benchmarks, analysis.settings.min_experts, analysis.standard_label)
    lines += [
        f"## {heading}",
        "",
        benchmarks,
        "",
    ]
    if standards:
        lines += ["## Standard setting: how often each pass mark misjudges", ""]
        lines += [*[f"- {n}" for n in analysis.standards.notes], "", _markdown_table(standards["marks"]), ""]
        lines += [f"### Leaving one expert out (rule '{analysis.settings.benchmark_rule}')", ""]
        lines += [_markdown_table(standards["loo"]), "", "### What each rule does to the course", ""]
        lines += [_markdown_table(standards["rules"]), ""]
    if analysis.reliability is not None:
        lines += ["## Reliability", "", *[f"- {n}" for n in analysis.reliability.notes], ""]
        lines += ["### Test-retest (benchmarked metrics)", "", _markdown_table(retest), "", consistency, ""]
        for name, table in raters:
            lines += [f"### Inter-rater agreement: {name}", "", _markdown_table(table), ""]
    lines += ["## Trainees", "", _markdown_table(trainee_summary(analysis)), ""]
    if feedback:
        lines += ["### What each trainee should work on next", "", FEEDBACK_BASIS, ""]
        for code, items in feedback:
            lines += [f"#### {code}", ""]
            lines += [f"{n}. **{i['kind']}**: {i['line']}" for n, i in enumerate(items["work_on"], start=1)]
            lines += [] if items["work_on"] else ["Nothing worse than the experts' middle half."]
            lines += ["", *[f"- Strength: {i['line']}" for i in items["strengths"]], ""]
    if analysis.left_out:
        lines += ["### Participants not in this analysis, and why", ""]
        lines += [_markdown_table(pd.DataFrame(analysis.left_out)), ""]
    lines += [f"![learning curve]({p})" for p in learning] + [""]
    lines += ["## Learning-curve fits", "", _markdown_table(_curves_for_reading(curves)), ""]
    lines += [
        f"## Metric definitions (registry version {REGISTRY_VERSION})",
        "",
        _markdown_table(registry),
        "",
    ]
    (folder / "report.md").write_text("\n".join(lines), encoding="utf-8")
    return folder / "report.html"
