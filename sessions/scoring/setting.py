"""The two acts on a study's standard that read its declared analysis: setting a new version of the
standard from the analysis of today (:func:`set_standard`) and judging the history under the newest
version (:func:`rejudge`, logged). They sit above :mod:`sessions.scoring.analysis`, which reads the
standards (:mod:`sessions.scoring.standards`) and the kept verdicts (:mod:`sessions.scoring.verdicts`)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import pandas as pd

from metrics.session.registry import REGISTRY_VERSION
from metrics.study.analysis import practice_mask
from metrics.study.proficiency import mark_intervals
from sessions.catalog import Catalog, CatalogError, WrongState, now
from sessions.catalog.models import Rejudgement, Standard, Verdict
from sessions.catalog.standards import latest_version, session_ids, verdicts_of
from sessions.scoring.analysis import analyse_catalog_study
from sessions.scoring.standards import StandardRecord, set_command, standard_history, standard_record
from sessions.scoring.verdicts import judged_under, standard_version_ids


def set_standard(catalog: Catalog, study_name: str, task: str, author: str, note: str = "") -> StandardRecord:
    """Set a new version of the study's standard on ``task`` from the study's declared analysis of it
    today. Refused (WrongState, saying why) when no metric qualifies for a mark."""
    analysis, source = analyse_catalog_study(catalog, study_name, {"task": task}, standard="candidate")
    benchmarks = analysis.benchmarks.dropna(subset=["benchmark"])
    if benchmarks.empty:
        why = next(
            (n for n in analysis.notes if n.startswith("No standard")), "no metric qualifies for a mark"
        )
        raise WrongState(f"no standard can be set for {task} in study {study_name!r}: {why}")
    settings = analysis.settings
    practice = analysis.sessions[practice_mask(analysis.sessions)]
    skilled = practice[practice[settings.group_col] == settings.skilled_group]
    intervals = mark_intervals(
        practice,
        list(benchmarks["metric"]),
        settings.group_col,
        settings.skilled_group,
        settings.cluster_col,
        settings.benchmark_rule,
        seed=settings.seed,
    )
    marks = [
        {
            "metric": row.metric,
            "benchmark": float(row.benchmark),
            "better": row.better,
            "pass_if": row.pass_if,
            "experts": int(row.experts),
            "interval": [v if math.isfinite(v) else None for v in intervals[row.metric]],  # JSON: no NaN
        }
        for row in benchmarks.itertuples()
    ]
    with catalog.session() as orm:
        study = catalog.study(orm, study_name)
        row = Standard(
            study_id=study.id,
            task=task,
            version=latest_version(orm, study.id, task) + 1,
            rule=settings.benchmark_rule,
            marks=marks,
            experts=sorted(map(str, pd.unique(skilled[settings.cluster_col]))),
            sessions=sorted(map(str, skilled["session_id"])),
            min_experts=settings.min_experts,
            registry_version=REGISTRY_VERSION,
            analysis_version=source.version,
            set_by=author,
            set_at=now(),
            note=note,
        )
        orm.add(row)
        orm.flush()
        return standard_record(study, row)


@dataclass(frozen=True)
class RejudgeResult:
    version: int
    sessions: int
    changed: int


def rejudge(catalog: Catalog, study_name: str, task: str, author: str, reason: str) -> RejudgeResult:
    """Judge every scored session of ``task`` in the study under the newest version of its standard,
    replacing the verdicts they kept, and log it (who, when, why, how many changed)."""
    if not reason.strip():
        raise CatalogError("say why the history is re-judged (--reason): it is kept in the standard's log")
    versions = standard_history(catalog, study_name, task)
    if not versions:
        raise WrongState(
            f"study {study_name!r} has no standard on {task} to re-judge under; set one first with "
            f"`{set_command(study_name, task)}`"
        )
    newest = versions[-1]
    analysis, _ = analyse_catalog_study(catalog, study_name, {"task": task})
    judged = judged_under(analysis, newest)
    kept = analysis.proficiency
    uids = [str(u) for u in kept["session_id"]]
    ids = standard_version_ids(catalog, study_name, task)
    stamp = now()
    changed = 0
    with catalog.session() as orm:
        found = session_ids(orm, uids)
        verdicts = verdicts_of(orm, found.values())
        for i, uid in enumerate(uids):
            passed = bool(judged.at[i, "passed"])
            changed += passed != bool(kept.at[i, "passed"])
            verdict = verdicts.get(found[uid])
            if verdict is None:
                verdict = Verdict(session_id=found[uid])
                orm.add(verdict)
            verdict.standard_id = ids[newest.version]
            verdict.passed = passed
            verdict.judged_at = stamp
            verdict.how = f"re-judged under v{newest.version} by {author}"[:300]
        orm.add(
            Rejudgement(
                standard_id=ids[newest.version],
                judged_by=author,
                judged_at=stamp,
                reason=reason.strip(),
                sessions=len(uids),
                changed=changed,
            )
        )
    return RejudgeResult(newest.version, len(uids), changed)
