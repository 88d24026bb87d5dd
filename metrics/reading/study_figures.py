"""The study report's figures: box plots per group, ROC curves and learning curves, each saved as PNG
and SVG in the report's ``figures`` folder."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from matplotlib.ticker import MaxNLocator
from sklearn.metrics import roc_curve

from metrics.reading.figures import new_figure
from metrics.reading.tables import display_scale, participant_medians
from metrics.session.registry import display_name
from metrics.study.analysis import StudyAnalysis, oriented, practice_mask
from metrics.study.learning import MODELS as LEARNING_MODELS

FIGURE_FORMATS = ("png", "svg")


def save_figure(figure, folder: Path, name: str) -> str:
    for kind in FIGURE_FORMATS:
        figure.savefig(folder / f"{name}.{kind}", dpi=100)
    return f"figures/{name}.png"


def box_plot_figure(analysis: StudyAnalysis, folder: Path) -> str:
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
        axis.set_title(display_name(metric) + (" *" if metric in significant else ""), fontsize=9)
        axis.set_ylabel(label, fontsize=8)
        axis.tick_params(labelsize=7)
    for axis in axes.ravel()[len(metrics) :]:
        axis.set_visible(False)
    figure.suptitle(
        f"Per-participant medians by {settings.group_col} (* discriminates after Holm)", fontsize=10
    )
    figure.tight_layout()
    return save_figure(figure, folder, "box_plots")


def roc_figure(analysis: StudyAnalysis, folder: Path) -> str:
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
        axis.plot(fpr, tpr, label=f"{display_name(metric)} (AUC {area:.2f})")
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
    return save_figure(figure, folder, "roc")


MAX_LEARNING_PANELS = 8
MAX_TRAINEES_DRAWN = 24


def learning_curve_figures(analysis: StudyAnalysis, folder: Path) -> list[str]:
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
        axis.set_ylabel(f"{display_name(bench.metric)} ({label})", fontsize=8)
        axis.set_title(f"{display_name(bench.metric)} ({bench.better} is better)", fontsize=9)
        axis.legend(fontsize=7)
    for axis in axes.ravel()[len(benchmarks) :]:
        axis.set_visible(False)
    figure.tight_layout()
    return [save_figure(figure, folder, "learning_curves")]
