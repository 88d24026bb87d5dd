"""One session against the experts: the study's expert band per metric, read by the metric's direction.

The dashboard's session page and ``vascsim sessions show`` both call
:func:`session_against_experts`, so a value reads the same wherever it is shown; the reading itself
is :func:`metrics.reading.band.against_band` (re-exported here).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import pandas as pd

from metrics.errors import GroupsMissing
from metrics.reading.band import against_band, expert_quartiles
from metrics.reading.feedback import session_feedback
from metrics.session.registry import REGISTRY_VERSION, display_name
from metrics.units import shown
from sessions.catalog import Catalog
from sessions.catalog.results import group_metric_values, stitch_values, task_id_named
from sessions.scoring.analysis import analyse_catalog_study
from sessions.status import SCORABLE
from sim.errors import VascsimError

EXPERT_GROUP = "expert"

__all__ = [
    "EXPERT_GROUP",
    "SessionReview",
    "against_band",
    "expert_band",
    "review_session",
    "session_against_experts",
    "session_stitches",
]


def expert_band(catalog: Catalog, study_id: int, task_id: int) -> dict[str, dict]:
    """Per metric, the quartiles of the study's expert sessions on the same task (current registry)."""
    with catalog.session() as orm:
        rows = group_metric_values(orm, study_id, EXPERT_GROUP, task_id, SCORABLE, REGISTRY_VERSION)
    return expert_quartiles(pd.DataFrame(rows, columns=["metric", "value"]))


def session_against_experts(catalog: Catalog, uid: str) -> list[dict]:
    """A session's current-registry metrics against its study's expert band on the same task."""
    with catalog.session() as orm:
        row = catalog.recorded_session(orm, uid)
        values = {
            m.metric: m.value
            for m in sorted(row.metrics, key=lambda m: m.id)
            if m.registry_version == REGISTRY_VERSION
        }
        study_id, task_id = row.participant.study_id, row.task_id
    return against_band(values, expert_band(catalog, study_id, task_id))


def session_stitches(catalog: Catalog, uid: str) -> list[dict]:
    """A session's stitches (current registry), one dict each: ``stitch`` and each stored quantity
    (:data:`metrics.signals.placement.STITCH_QUANTITIES`, SI units; None where it does not apply)."""
    with catalog.session() as orm:
        row = catalog.recorded_session(orm, uid)
        results = stitch_values(orm, row.id, REGISTRY_VERSION)
    stitches: dict[int, dict] = {}
    for stitch, quantity, value in results:
        stitches.setdefault(stitch, {"stitch": stitch})[quantity] = value
    return list(stitches.values())


@dataclass(frozen=True)
class SessionReview:
    """How one session went, as a trainee is told on the station's feedback screen and by ``vascsim run``.

    verdict: "pass", "not yet" (below the study's standard on at least one benchmark) or "no standard"
    (the study has none for this task yet: ``standard`` says why); benchmarks: one dict per
    benchmarked metric (metric, value, mark, direction, pass condition, passed, and a line in display
    units and direction words);
    work_on and strengths: :func:`metrics.reading.feedback.session_feedback`'s items.
    """

    uid: str
    task: str
    trial: int
    verdict: str
    standard: str
    benchmarks: list[dict]
    work_on: list[dict]
    strengths: list[dict]
    has_band: bool = True
    """Whether an expert of the study has a scored session of the task (else nothing to compare with)."""

    def as_dict(self) -> dict:
        return dataclasses.asdict(self)


def review_session(catalog: Catalog, uid: str, rows: list[dict] | None = None) -> SessionReview:
    """The session against its study's standard on its task (the study's declared analysis, with this
    session's task) and against the experts' band: one function, so the station's feedback screen and
    ``vascsim run`` say the same thing (what to work on is the same function as ``sessions show``'s).
    ``rows``: the session against the experts' band when the caller has read it already."""

    with catalog.session() as orm:
        row = catalog.recorded_session(orm, uid)
        study, task, trial = row.participant.study.name, row.task.name, row.trial
    rows = session_against_experts(catalog, uid) if rows is None else rows
    verdict, standard, benchmarks, marks = _against_standard(catalog, study, task, uid, rows)
    feedback = session_feedback(rows, benchmarks=marks)
    has_band = any(row["expert_q1"] is not None for row in rows)
    return SessionReview(
        uid, task, trial, verdict, standard, benchmarks, feedback["work_on"], feedback["strengths"], has_band
    )


def _against_standard(
    catalog: Catalog, study: str, task: str, uid: str, rows: list[dict]
) -> tuple[str, str, list[dict], pd.DataFrame | None]:
    """(verdict, the standard in words, each benchmark's reading, the benchmarks table or None)."""

    if all(row["expert_q1"] is None for row in rows):  # the band is the experts' on this task
        why = f"no standard for {task} yet: no expert of this study has a scored session of it"
        return "no standard", why, [], None
    try:
        analysis, _ = analyse_catalog_study(catalog, study, {"task": task})
    except GroupsMissing as error:  # a standard compares two groups: one has no scored session yet
        missing = " or ".join(repr(group) for group in error.absent)
        why = (
            f"no standard for {task} in this study yet: a standard compares two groups, and no "
            f"participant in group {missing} has a scored session of it"
        )
        return "no standard", why, [], None
    except VascsimError as error:  # the study's analysis cannot be run (yet): no verdict, and why
        return "no standard", f"no standard for {task} in this study yet: {error}", [], None
    sessions = analysis.sessions
    found = sessions.index[sessions["session_id"] == uid]
    if not len(found):
        return (
            "no standard",
            f"no standard for {task} in this study yet (this session is not analysed)",
            [],
            None,
        )
    if analysis.benchmarks.empty:
        counts = ", ".join(f"{n} {group}(s)" for group, n in analysis.validity.n_participants.items())
        why = (
            f"no standard for {task} in this study yet: no metric shows the experts clearly better "
            f"({counts} so far)"
        )
        return "no standard", why, [], None
    index = found[0]
    by_metric = {r["metric"]: r for r in rows}
    marks, label = analysis.benchmarks, ""
    if "standard_version" in analysis.proficiency.columns:  # the version this session was judged under
        label, marks = analysis.judged_under[int(analysis.proficiency.at[index, "standard_version"])]
    benchmarks = []
    for bench in marks.itertuples():
        if bench.benchmark != bench.benchmark:  # NaN: no expert values
            continue
        column = f"pass_{bench.metric}"
        value = by_metric.get(bench.metric, {}).get("value")
        passed = analysis.proficiency.at[index, column] if column in analysis.proficiency else None
        passed = None if passed is None or pd.isna(passed) else bool(passed)
        unit = by_metric.get(bench.metric, {}).get("unit", "")
        reading = {True: "met", False: "not met", None: "not measured"}[passed]
        benchmarks.append(
            {
                "metric": bench.metric,
                "value": value,
                "mark": float(bench.benchmark),
                "better": bench.better,
                "pass_if": bench.pass_if,
                "passed": passed,
                "line": f"{display_name(bench.metric)} {shown(value, unit)}: {reading}, the standard is "
                f"{bench.pass_if} ({bench.better} is better)",
            }
        )
    passed = bool(analysis.proficiency.at[index, "passed"])
    if label:
        rule = analysis.settings.benchmark_rule
        standard = f"the study's {label} on {task}: {len(benchmarks)} metric(s), rule {rule}"
    else:
        experts = int(marks["experts"].max())
        standard = (
            f"the study's candidate benchmarks on {task} (no standard set): {len(benchmarks)} metric(s), "
            f"rule {analysis.settings.benchmark_rule}, from {experts} expert(s)"
            + (", provisional" if experts < analysis.settings.min_experts else "")
        )
    return ("pass" if passed else "not yet"), standard, benchmarks, marks


def experts_on_task(catalog: Catalog, study: str, task: str) -> bool:
    """Whether any expert of ``study`` has a scored session of ``task`` (a standard needs them)."""
    with catalog.session() as orm:
        study_id = catalog.study(orm, study).id
        task_id = task_id_named(orm, task)
    return task_id is not None and bool(expert_band(catalog, study_id, task_id))
