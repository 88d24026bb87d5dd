"""Verdicts that stay: every session is judged once, under the version of its study's standard in
force when it was recorded, and keeps that verdict.

Setting a newer version (:func:`sessions.scoring.standards.set_standard`) judges the sessions recorded from
then on; it does not reach back. A session recorded before the first version was set is judged under
the first (setting a course's first standard judges its history). Judging history under a newer
version is an explicit act, :func:`rejudge`, logged with who, when, why and how many verdicts
changed. Each verdict names the version it was given under, and every front-end shows it from the
same table (:func:`kept_verdicts`, called by :func:`sessions.scoring.analysis.analyse_catalog_study`).
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime

import pandas as pd
from sqlalchemy.exc import IntegrityError

from metrics.study.analysis import StudyAnalysis, session_judge, with_verdicts
from sessions.catalog import Catalog, CatalogError, WrongState, now
from sessions.catalog.models import Rejudgement, Verdict
from sessions.catalog.standards import (
    kept_verdict_rows,
    rejudgement_log,
    session_ids,
    standard_ids,
    verdicts_of,
)
from sessions.scoring.standards import StandardRecord, set_command, standard_history, standards_command


def version_in_force(versions: list[StandardRecord], started_at: datetime | None) -> StandardRecord:
    """The newest of ``versions`` (oldest first) set at or before ``started_at``; the first version for a
    session recorded before any was set."""
    found = [v for v in versions if started_at is not None and v.set_at <= started_at]
    return found[-1] if found else versions[0]


def _judged(analysis: StudyAnalysis, version: StandardRecord) -> pd.DataFrame:
    """Every session of ``analysis`` judged against ``version``'s marks as set."""
    marks = version.benchmarks()
    marks = marks[marks["metric"].isin(analysis.sessions.columns)].reset_index(drop=True)
    return session_judge(analysis.settings)(analysis.sessions, marks)


def _standard_ids(catalog: Catalog, study_name: str, task: str) -> dict[int, int]:
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
    judged = {v: _judged(analysis, by_version[v]) for v in sorted({v for v, _ in chosen})}
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
        ids = _standard_ids(catalog, study_name, task)
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


@dataclass(frozen=True)
class RejudgeResult:
    version: int
    sessions: int
    changed: int


def rejudge(catalog: Catalog, study_name: str, task: str, author: str, reason: str) -> RejudgeResult:
    """Judge every scored session of ``task`` in the study under the newest version of its standard,
    replacing the verdicts they kept, and log it (who, when, why, how many changed)."""
    from sessions.scoring.analysis import analyse_catalog_study

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
    judged = _judged(analysis, newest)
    kept = analysis.proficiency
    uids = [str(u) for u in kept["session_id"]]
    ids = _standard_ids(catalog, study_name, task)
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
