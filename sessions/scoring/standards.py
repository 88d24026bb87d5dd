"""A study's standard on a task: pass marks set once, stored, versioned, and never recomputed behind
anyone's back.

Marks computed afresh whenever a page is built move when anyone records a session: adding four
trainee sessions once changed the demo's benchmarks from four metrics to two and flipped passes of
people who had done nothing. A standard is therefore *set* (``vascsim standards set``, the demo sets
its own): :func:`sessions.scoring.setting.set_standard` runs the study's declared analysis on the
task, keeps only marks that point the right way (:func:`metrics.study.analysis.benchmark_choice`),
and stores them with the experts and sessions they came from, the rule, the registry and analysis
versions, who and when. From then on every analysis of the task
(:func:`sessions.scoring.analysis.analyse_catalog_study`) judges against the newest version's marks
as stored, and says which version it used. A new version applies from when it is set; the older ones
stay readable (:func:`standard_history`).
"""

from __future__ import annotations

import shlex
from dataclasses import dataclass
from datetime import datetime

import pandas as pd

from metrics.study.analysis import StudyAnalysis, practice_mask
from metrics.study.proficiency import BENCHMARK_COLUMNS, mark_drift, mark_intervals, proficiency_benchmarks
from sessions.catalog import Catalog
from sessions.catalog.models import Standard, Study
from sessions.catalog.standards import standards_of


@dataclass(frozen=True)
class StandardRecord:
    """One version of a study's standard on a task, as it was set."""

    study: str
    task: str
    version: int
    rule: str
    marks: list[dict]
    experts: list[str]
    sessions: list[str]
    min_experts: int
    registry_version: str
    analysis_version: int | None
    set_by: str
    set_at: datetime
    note: str

    @property
    def provisional(self) -> bool:
        """Set from fewer experts than the analysis' rule asks for."""
        return len(self.experts) < self.min_experts

    def label(self) -> str:
        """How every page, report and the CLI name it: "standard v2, set 2026-12-05 from 4 experts
        (12 sessions)", and "provisional" when too few experts set it."""
        text = (
            f"standard v{self.version}, set {self.set_at:%Y-%m-%d} from {len(self.experts)} expert(s) "
            f"({len(self.sessions)} sessions)"
        )
        if self.provisional:
            text += f", provisional (the rule asks for {self.min_experts} experts)"
        return text

    def benchmarks(self) -> pd.DataFrame:
        """The marks as a benchmarks table (the columns of
        :func:`metrics.study.proficiency.proficiency_benchmarks`)."""
        rows = [
            {**{c: mark[c] for c in BENCHMARK_COLUMNS if c != "rule"}, "rule": self.rule}
            for mark in self.marks
        ]
        return pd.DataFrame(rows, columns=BENCHMARK_COLUMNS)

    def as_dict(self) -> dict:
        return {
            "study": self.study,
            "task": self.task,
            "version": self.version,
            "label": self.label(),
            "rule": self.rule,
            "marks": self.marks,
            "experts": self.experts,
            "sessions": self.sessions,
            "provisional": self.provisional,
            "min_experts": self.min_experts,
            "registry_version": self.registry_version,
            "analysis_version": self.analysis_version,
            "set_by": self.set_by,
            "set_at": self.set_at.isoformat(),
            "note": self.note,
        }


def standard_record(study: Study, row: Standard) -> StandardRecord:
    return StandardRecord(
        study.name,
        row.task,
        row.version,
        row.rule,
        list(row.marks),
        list(row.experts),
        list(row.sessions),
        row.min_experts,
        row.registry_version,
        row.analysis_version,
        row.set_by,
        row.set_at,
        row.note,
    )


def standard_history(catalog: Catalog, study_name: str, task: str | None = None) -> list[StandardRecord]:
    """Every version set for the study (of ``task`` when given), oldest first."""
    with catalog.session() as orm:
        study = catalog.study(orm, study_name)
        return [standard_record(study, row) for row in standards_of(orm, study.id, task)]


def current_standard(catalog: Catalog, study_name: str, task: str) -> StandardRecord | None:
    """The newest version of the study's standard on ``task``; None when none was set."""
    versions = standard_history(catalog, study_name, task)
    return versions[-1] if versions else None


def standard_drift(analysis: StudyAnalysis, record: StandardRecord) -> list[dict]:
    """The marks of ``record`` that the experts in ``analysis`` (today's data) would move beyond the
    interval each had when it was set (:func:`metrics.study.proficiency.mark_drift`). A mark set before
    marks kept their interval gets it now, from the very expert sessions the standard names
    (:func:`set_time_intervals`): the check never skips a mark for its age."""
    settings = analysis.settings
    practice = analysis.sessions[practice_mask(analysis.sessions)]
    marks = [
        m
        for m in set_time_intervals(analysis, record)
        if m["metric"] in practice.columns and m.get("interval")
    ]
    if not marks or not (practice[settings.group_col] == settings.skilled_group).any():
        return []
    metrics = [m["metric"] for m in marks]
    today = proficiency_benchmarks(
        practice, metrics, settings.group_col, settings.skilled_group, settings.cluster_col, record.rule
    )
    return mark_drift(marks, today)


def set_time_intervals(analysis: StudyAnalysis, record: StandardRecord) -> list[dict]:
    """``record``'s marks, each with its interval: as stored, or, for a mark stored without one
    (set before marks kept it), the same bootstrap over the expert sessions the standard names
    (``record.sessions``, as scored in ``analysis``) with the standard's rule; for the contrasting
    rule the unskilled participants' sessions in ``analysis`` stand in for those of the day."""
    missing = [m["metric"] for m in record.marks if not m.get("interval")]
    if not missing:
        return list(record.marks)
    settings = analysis.settings
    practice = analysis.sessions[practice_mask(analysis.sessions)]
    named = practice["session_id"].astype(str).isin(record.sessions)
    if record.rule == "contrasting":
        named |= practice[settings.group_col] != settings.skilled_group
    scored = [m for m in missing if m in practice.columns]
    intervals = mark_intervals(
        practice[named],
        scored,
        settings.group_col,
        settings.skilled_group,
        settings.cluster_col,
        record.rule,
        seed=settings.seed,
    )
    return [
        m
        if m.get("interval") or m["metric"] not in intervals
        else {**m, "interval": list(intervals[m["metric"]])}
        for m in record.marks
    ]


def standards_command(action: str, study_name: str, task: str) -> str:
    """``vascsim standards ACTION`` for a study's task, quoted so it pastes as shown."""
    return f"vascsim standards {action} --study {shlex.quote(study_name)} --task {shlex.quote(task)}"


def set_command(study_name: str, task: str) -> str:
    """The command that sets a standard."""
    return standards_command("set", study_name, task)
