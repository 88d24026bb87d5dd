"""The study's tables as a person reads them (display units, directions, intervals in one cell) and
as the report writes them to CSV (SI, every header naming its unit): one function per table, shared
by the report, the dashboard and the CLI so the same question gets the same answer everywhere."""

from __future__ import annotations

import html
import math

import numpy as np
import pandas as pd
from markupsafe import Markup

from metrics.reading.feedback import RECENT_SESSIONS, participant_feedback
from metrics.session.registry import REGISTRY, display_name
from metrics.study.analysis import StudyAnalysis, metric_unit, practice_mask
from metrics.study.reliability import agreement_shown
from metrics.study.validity import aggregate_by_participant
from metrics.units import display_unit, in_display_units, interval_text, significant


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


def table_text(value) -> str:
    if value is None or value is pd.NA or (isinstance(value, float) and math.isnan(value)):
        return ""
    if isinstance(value, bool | np.bool_):
        return "yes" if value else "no"
    if isinstance(value, float | np.floating):
        return significant(float(value))
    return str(value)


def markdown_table(frame: pd.DataFrame) -> str:
    header = "| " + " | ".join(map(str, frame.columns)) + " |"
    rule = "| " + " | ".join("---" for _ in frame.columns) + " |"
    body = ["| " + " | ".join(table_text(v) for v in row) + " |" for row in frame.itertuples(index=False)]
    return "\n".join([header, rule, *body])


def html_table(frame: pd.DataFrame) -> Markup:
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
    """Per trainee (as in the trainee table), :func:`metrics.reading.feedback.participant_feedback`."""
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


def composite_weights_for_reading(composite, skilled_group: str = "expert") -> pd.DataFrame:
    """The composite's weights as a reader takes them: each metric named in words, its weight (the
    rank-biserial correlation of its values with the skilled group, -1 to 1) and which way the skilled
    group lies, largest weights first; metrics that carry none are left out (the full table, by key,
    is tables/composite_weights.csv)."""
    columns = ["metric", "weight", f"{skilled_group} values"]
    if composite is None:
        return pd.DataFrame(columns=columns)
    weights = composite.weights[composite.weights.abs() > 0].sort_values(key=np.abs, ascending=False)
    return pd.DataFrame(
        {
            columns[0]: [display_name(m) for m in weights.index],
            columns[1]: [f"{w:+.2f}" for w in weights],
            columns[2]: ["higher" if w > 0 else "lower" for w in weights],
        },
        columns=columns,
    )


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


def curves_for_reading(curves: pd.DataFrame) -> pd.DataFrame:
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
