"""Construct validity: do the metrics separate the groups they should, and how sure can we be?

Trials cluster within participants: by default each participant contributes one
value per metric (the median of their sessions) and every test, effect size and
interval is at the participant level. ``level="trial"`` uses every session as a
row; its row-level p treats sessions as independent and overstates the evidence,
so a metric is flagged only when a test that permutes the group labels across
participants (``p_cluster``) agrees, and AUC intervals count participants.

``auc`` is oriented: P(a skilled participant does better than an unskilled one),
by the metric's registry direction; ``auc_raw`` is P(first group > second).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from metrics.errors import GroupsMissing, MetricsError
from metrics.session.registry import REGISTRY
from metrics.study.composite import CompositeValidation, validate_composite
from metrics.study.statistics import (
    auc_interval,
    cluster_permutation_test,
    holm,
    interval_is_informative,
    mann_whitney,
    minimum_exact_p,
    oriented_auc,
)

LEVELS = ("participant", "trial")


@dataclass(frozen=True)
class ConstructValidityResult:
    """Per-metric table, composite-score validation and the notes a reader must see."""

    table: pd.DataFrame
    composite: CompositeValidation | None
    level: str
    group_col: str
    groups: tuple[str, str]
    cluster_col: str
    n_participants: dict[str, int]
    n_sessions: dict[str, int]
    alpha: float
    notes: list[str] = field(default_factory=list)

    def discriminating(self) -> list[str]:
        """Metrics flagged as discriminating (Holm p below alpha, and at trial level the participant-level
        permutation test agreeing), in the expected direction where one is known."""
        table = self.table
        chosen = table[table["discriminates"] & table["as_expected"].fillna(True).astype(bool)]
        return chosen["metric"].tolist()


def aggregate_by_participant(
    table: pd.DataFrame, group_col: str, cluster_col: str, metrics: Sequence[str]
) -> pd.DataFrame:
    """One row per participant: the median of each metric over their sessions."""
    labels = table.groupby(cluster_col)[group_col].nunique()
    mixed = labels[labels > 1]
    if not mixed.empty:
        raise MetricsError(
            f"participant(s) {', '.join(map(str, mixed.index[:5]))} have more than one {group_col!r}; "
            "a per-session label needs level='trial'"
        )
    grouped = table.groupby(cluster_col, sort=True)
    medians = grouped[list(metrics)].median()
    medians[group_col] = grouped[group_col].first()
    medians["sessions"] = grouped.size()
    return medians.reset_index()


def _metric_columns(table: pd.DataFrame, metrics: Sequence[str] | None) -> list[str]:
    if metrics is not None:
        missing = [m for m in metrics if m not in table.columns]
        if missing:
            raise MetricsError(f"table lacks metric column(s) {', '.join(missing)}")
        return list(metrics)
    return [m.name for m in REGISTRY if m.name in table.columns and table[m.name].notna().any()]


def construct_validity(
    table: pd.DataFrame,
    group_col: str,
    groups: Sequence[str],
    cluster_col: str = "participant_id",
    level: str = "participant",
    metrics: Sequence[str] | None = None,
    skilled_group: str | None = None,
    alpha: float = 0.05,
    n_boot: int = 2000,
    seed: int = 0,
) -> ConstructValidityResult:
    """Compare ``groups[0]`` against ``groups[1]`` on every metric column.

    group_col: the label validated against (e.g. ``"label"`` for self-reported
    level, or a column derived from a GRS/OSATS rating). skilled_group (default
    ``groups[0]``) orients "as expected" against each metric's registry direction
    and the composite score. The AUC is P(first group's value > second's).
    """
    if level not in LEVELS:
        raise MetricsError(f"level must be 'participant' or 'trial'; got {level!r}")
    if len(groups) != 2 or groups[0] == groups[1]:
        raise MetricsError(f"groups must name two different groups; got {list(groups)!r}")
    for column in (group_col, cluster_col):
        if column not in table.columns:
            raise MetricsError(f"table has no column {column!r}")
    present = set(table[group_col].dropna().unique())
    absent = [g for g in groups if g not in present]
    if absent:
        raise GroupsMissing(
            f"group(s) {', '.join(map(repr, absent))} not found in column {group_col!r} "
            f"(it holds {', '.join(map(repr, sorted(map(str, present))))})",
            absent,
        )
    skilled_group = groups[0] if skilled_group is None else skilled_group
    if skilled_group not in groups:
        raise MetricsError(f"skilled_group {skilled_group!r} is not one of {list(groups)!r}")
    names = _metric_columns(table, metrics)
    rows_in = table[table[group_col].isin(groups)].reset_index(drop=True)
    data = (
        aggregate_by_participant(rows_in, group_col, cluster_col, names)
        if level == "participant"
        else rows_in
    )
    first = (data[group_col] == groups[0]).to_numpy()
    clusters = data[cluster_col].to_numpy()
    n_participants = {g: int(rows_in.loc[rows_in[group_col] == g, cluster_col].nunique()) for g in groups}
    n_sessions = {g: int((rows_in[group_col] == g).sum()) for g in groups}

    participants_of = {
        g: data.loc[data[group_col] == g].groupby(cluster_col)[list(names)].count() for g in groups
    }
    records = []
    for name in names:
        values = data[name].to_numpy(dtype=np.float64)
        x, y = values[first], values[~first]
        x, y = x[~np.isnan(x)], y[~np.isnan(y)]
        better = REGISTRY[name].better if name in REGISTRY else ""
        record = {"metric": name, "unit": REGISTRY[name].unit if name in REGISTRY else "", "better": better}
        for label, part in ((groups[0], x), (groups[1], y)):
            record[f"n_{label}"] = int(part.size)
            quartiles = np.quantile(part, [0.25, 0.5, 0.75]) if part.size else [math.nan] * 3
            record[f"median_{label}"] = float(quartiles[1])
            record[f"q1_{label}"] = float(quartiles[0])
            record[f"q3_{label}"] = float(quartiles[2])
        # participants with a value of this metric, per group: the independent units
        units = [int((participants_of[g][name] > 0).sum()) for g in groups]
        skilled_first = skilled_group == groups[0]
        record.update(_comparison(values, first, clusters, x, y, units, level, better, skilled_first))
        if record["auc"] == record["auc"] and record["auc_raw"] != 0.5:
            record["direction"] = f"{'higher' if record['auc_raw'] > 0.5 else 'lower'} in {groups[0]}"
        elif record["auc"] == record["auc"]:
            record["direction"] = "no difference"
        else:
            record["direction"] = "not computed"
        undecided = not better or record["auc"] != record["auc"] or record["auc"] == 0.5
        record["as_expected"] = None if undecided else record["auc"] > 0.5
        records.append(record)
    result_table = pd.DataFrame(records)
    if result_table.empty:
        raise MetricsError("no metric column has values for both groups")
    result_table["p_holm"] = holm(result_table["p_value"].to_numpy())
    result_table["p_cluster_holm"] = holm(result_table["p_cluster"].to_numpy())
    # a flag needs the participant-aware test to agree: never pseudo-replicated rows alone
    flagged = (result_table["p_holm"] < alpha) & (result_table["p_cluster_holm"] < alpha)
    result_table["discriminates"] = flagged
    order = [c for c in result_table.columns if c not in ("p_holm", "p_cluster_holm", "discriminates")]
    position = order.index("p_cluster") + 1
    order[position:position] = ["p_holm", "p_cluster_holm", "discriminates"]
    result_table = result_table[order]

    notes = [_level_note(level, n_participants, n_sessions)]
    notes += _power_notes(n_participants[groups[0]], n_participants[groups[1]], len(names), alpha)
    n_x, n_y = n_participants[groups[0]], n_participants[groups[1]]
    if not interval_is_informative(n_x, n_y, alpha):
        notes.append(
            f"No AUC intervals: with {n_x} and {n_y} participants no result could reach p < {alpha}, "
            "so an interval would only restate that the design is too small."
        )
    composite = None
    if data[cluster_col].nunique() >= 3:
        composite = validate_composite(data, names, group_col, skilled_group, cluster_col, n_boot, seed)
    return ConstructValidityResult(
        result_table,
        composite,
        level,
        group_col,
        (str(groups[0]), str(groups[1])),
        cluster_col,
        n_participants,
        n_sessions,
        alpha,
        notes,
    )


def _level_note(level: str, n_participants: dict[str, int], n_sessions: dict[str, int]) -> str:
    counts = ", ".join(
        f"{g}: {n_participants[g]} participants / {n_sessions[g]} sessions" for g in n_participants
    )
    if level == "participant":
        return f"Analysis at participant level (median of each participant's sessions); {counts}."
    return (
        f"Analysis at trial level on request ({counts}): p-values treat sessions as independent and so "
        "overstate the evidence, so a metric is flagged only when the test permuting labels across "
        "participants agrees; AUC intervals count participants."
    )


def _comparison(values, first, clusters, x, y, units, level, better, skilled_first) -> dict:
    """Test, effect sizes, oriented AUC and its interval for one metric."""
    if not (x.size and y.size):
        nan = math.nan
        return dict(
            u=nan,
            p_value=nan,
            p_method="",
            p_cluster=nan,
            cliffs_delta=nan,
            auc=nan,
            auc_raw=nan,
            auc_ci_low=nan,
            auc_ci_high=nan,
        )
    test = mann_whitney(x, y)
    auc = oriented_auc(test.auc, skilled_first, better != "lower")
    if interval_is_informative(*units):
        # the independent units are participants, also when rows are trials
        low, high = auc_interval(auc, *units)
    else:
        low, high = math.nan, math.nan
    if level == "trial":
        p_cluster = cluster_permutation_test(values, first, clusters).p_value
    else:
        p_cluster = test.p_value  # one row per participant: the rank test is the permutation test
    return dict(
        u=test.u,
        p_value=test.p_value,
        p_method=test.method,
        p_cluster=p_cluster,
        cliffs_delta=test.cliffs_delta,
        auc=auc,
        auc_raw=test.auc,
        auc_ci_low=low,
        auc_ci_high=high,
    )


def _power_notes(n_x: int, n_y: int, m: int, alpha: float) -> list[str]:
    """Power as the design allows it: counted in participants, whatever the level of the rows."""
    floor = minimum_exact_p(n_x, n_y)
    effects = "Only large effects can be detected; read effect sizes and intervals."
    smallest = (
        f"With {n_x} and {n_y} participants the smallest two-sided p any metric can reach is {floor:.3g} "
        f"(before Holm correction over {m} metrics)."
    )
    if floor * m > alpha:
        return [
            f"Little power. {smallest} No metric can reach p < {alpha} after correction; absence of "
            "significance here does not show the metrics fail to discriminate."
        ]
    if min(n_x, n_y) < 8:
        return [f"Small groups. {smallest} {effects}"]
    return [smallest]
