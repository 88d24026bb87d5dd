"""Verdicts that stay: every session is judged once, under the version of its study's standard in force
when it was recorded, and keeps that verdict.

Setting a newer version (:func:`sessions.scoring.setting.set_standard`) judges the sessions recorded
from then on; it does not reach back. A session recorded before the first version was set is judged
under the first (setting a course's first standard judges its history). Judging history under a
newer version is an explicit act, :func:`sessions.scoring.setting.rejudge`, logged with who, when,
why and how many verdicts changed. Each verdict names the version it was given under, and every
front-end shows it from the same table (:func:`kept_verdicts`, called by
:func:`sessions.scoring.analysis.analyse_catalog_study`).
"""

from __future__ import annotations

from datetime import datetime

import pandas as pd
from sqlalchemy.exc import IntegrityError

from metrics.study.analysis import StudyAnalysis, session_judge, with_verdicts
from sessions.catalog import Catalog, now
from sessions.catalog.models import Verdict
from sessions.catalog.standards import (
    kept_verdict_rows,
    rejudgement_log,
    standard_ids,
)
from sessions.scoring.standards import StandardRecord, standard_history, standards_command


def version_in_force(versions: list[StandardRecord], started_at: datetime | None) -> StandardRecord:
    """The newest of ``versions`` (oldest first) set at or before ``started_at``; the first version for a
    session recorded before any was set."""
    found = [v for v in versions if started_at is not None and v.set_at <= started_at]
    return found[-1] if found else versions[0]


def judged_under(analysis: StudyAnalysis, version: StandardRecord) -> pd.DataFrame:
    """Every session of ``analysis`` judged against ``version``'s marks as set."""
    marks = version.benchmarks()
    marks = marks[marks["metric"].isin(analysis.sessions.columns)].reset_index(drop=True)
    return session_judge(analysis.settings)(analysis.sessions, marks)


def standard_version_ids(catalog: Catalog, study_name: str, task: str) -> dict[int, int]:
    with catalog.session() as orm:
        return standard_ids(orm, catalog.study(orm, study_name).id, task)


def kept_verdicts(catalog: Catalog, study_name: str, task: str, analysis: StudyAnalysis) -> StudyAnalysis:
    """``analysis`` (judged against the newest standard on ``task``) with each session's kept verdict:
    the one stored, or, for a session judged for the first time, its verdict under the version in force
    when it was recorded, stored now. The proficiency table gains ``standard_version``; the trainees'
    passes, proficiency and retention follow the kept verdicts."""
    versions = standard_history(catalog, study_name, task)
    if not versions:
        return analysis
    by_version = {v.version: v for v in versions}
    uids = [str(u) for u in analysis.proficiency["session_id"]]
    with catalog.session() as orm:
        rows = kept_verdict_rows(orm, uids)
    known = {uid: (sid, started, passed, version) for uid, sid, started, passed, version in rows}
    chosen = []
    for uid in uids:
        sid, started, passed, version = known[uid]
        if version is None:
            chosen.append((version_in_force(versions, started).version, None))
        else:
            chosen.append((version, bool(passed)))
    judged = {v: judged_under(analysis, by_version[v]) for v in sorted({v for v, _ in chosen})}
    # each check as the session's own version reads it (pass_<metric>, and safety_<metric> and safe
    # in non-compensatory mode); the verdict itself is the one kept
    columns = sorted({c for frame in judged.values() for c in frame.columns if c != "passed"})
    proficiency = pd.DataFrame({"session_id": analysis.proficiency["session_id"]})
    for column in columns:
        proficiency[column] = pd.array(
            [
                judged[v].at[i, column] if column in judged[v].columns else pd.NA
                for i, (v, _) in enumerate(chosen)
            ],
            dtype="boolean",
        )
    fresh = [(i, v) for i, (v, kept) in enumerate(chosen) if kept is None]
    proficiency["passed"] = [
        bool(judged[v].at[i, "passed"]) if kept is None else kept for i, (v, kept) in enumerate(chosen)
    ]
    proficiency["standard_version"] = [v for v, _ in chosen]
    if fresh:
        ids = standard_version_ids(catalog, study_name, task)
        first = versions[0]
        stamp = now()
        try:
            with catalog.session() as orm:
                for i, v in fresh:
                    sid, started = known[uids[i]][:2]
                    how = (
                        f"recorded before v{first.version} was set; judged under it"
                        if started is None or started < first.set_at
                        else f"recorded under v{v}"
                    )
                    orm.add(
                        Verdict(
                            session_id=sid,
                            standard_id=ids[v],
                            passed=bool(proficiency.at[i, "passed"]),
                            judged_at=stamp,
                            how=how,
                        )
                    )
        except IntegrityError:
            pass  # another reader stored the same verdicts first; they are what this one computed
    result = with_verdicts(analysis, proficiency)
    result.judged_under = {
        v: (by_version[v].label(), by_version[v].benchmarks())
        for v in sorted(set(proficiency["standard_version"]))
    }
    newest = versions[-1].version
    older = int((proficiency["standard_version"] != newest).sum())
    if older:
        result.notes.append(
            f"{older} session(s) keep the verdicts they were given under an earlier version of the "
            f"standard (each says which); judge them under v{newest} with "
            f"`{standards_command('rejudge', study_name, task)} --reason ...`."
        )
    return result


def rejudgements(catalog: Catalog, study_name: str, task: str) -> list[dict]:
    """The standard's re-judging log on ``task``, oldest first."""
    with catalog.session() as orm:
        rows = rejudgement_log(orm, catalog.study(orm, study_name).id, task)
        return [
            {
                "version": version,
                "by": r.judged_by,
                "at": r.judged_at.isoformat(),
                "reason": r.reason,
                "sessions": r.sessions,
                "changed": r.changed,
            }
            for version, r in rows
        ]
