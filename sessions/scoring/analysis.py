"""A study's analysis, declared once in the catalog and computed by one function for every front-end.

``vascsim demo``, ``vascsim report``, the dashboard and exported reports all call
:func:`analyse_catalog_study`: the study's latest declared :class:`StudySettings`
(or, for a study that declared none, :func:`default_settings`), with any one-run
overrides applied and named in the analysis' notes. Declarations are versioned:
:func:`declare_analysis` adds a version (who, when, what changed) and never edits one.
"""

from __future__ import annotations

import dataclasses
import shlex
from dataclasses import dataclass
from typing import Any

import pandas as pd

from metrics.errors import MetricsError
from metrics.session.registry import REGISTRY, REGISTRY_VERSION
from metrics.study.analysis import StudyAnalysis, StudySettings, analyse_study
from metrics.study.proficiency import check_rule, drift_line
from sessions.catalog import Catalog, CatalogError, WrongState, now
from sessions.catalog.models import AnalysisDeclaration
from sessions.catalog.results import (
    imported_result_sessions,
    latest_declaration,
    registry_versions,
    study_sessions_with,
)
from sessions.catalog.store import CatalogStore
from sessions.scoring.ratings import study_ratings
from sessions.scoring.standards import current_standard, set_command, standard_drift
from sessions.scoring.verdicts import kept_verdicts
from sessions.status import SCORABLE
from sessions.tasks import task_spec
from sim.errors import VascsimError

DECLARABLE = (
    "group_col",
    "groups",
    "skilled_group",
    "level",
    "metrics",
    "benchmark_rule",
    "benchmark_metrics",
    "benchmark_override",
    "min_experts",
    "consecutive_passes",
    "progression_window",
    "non_compensatory",
    "retention_baseline",
    "baseline_trials",
    "rating_col",
    "learning_model",
    "alpha",
    "task",
)
"""The choices a study declares; the rest of StudySettings (seeds, resample counts) are the code's."""

_TUPLES = ("groups", "metrics", "benchmark_metrics")


@dataclass(frozen=True)
class AnalysisSource:
    """Where a computed analysis' settings came from: the declared version and what one run overrode."""

    version: int | None  # None: the study declared nothing and the defaults were used
    author: str
    overridden: dict[str, tuple[Any, Any]]  # name -> (declared, used)


def settings_from_json(data: dict, what: str) -> StudySettings:
    """StudySettings from a stored or submitted dictionary, every field checked; errors name the field."""
    if not isinstance(data, dict):
        raise CatalogError(f"{what}: an analysis declaration must be an object; got {type(data).__name__}")
    unknown = sorted(set(data) - set(DECLARABLE))
    if unknown:
        raise CatalogError(
            f"{what}: unknown analysis setting(s) {', '.join(unknown)}; known: {', '.join(DECLARABLE)}"
        )
    values: dict[str, Any] = {}
    for name, value in data.items():
        if name in _TUPLES:
            if value is None and name != "groups":
                values[name] = None
                continue
            if not isinstance(value, (list, tuple)) or not all(isinstance(v, str) and v for v in value):
                raise CatalogError(f"{what}: {name} must be a list of names; got {value!r}")
            values[name] = tuple(value)
        elif name in ("consecutive_passes", "retention_baseline", "min_experts"):
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                raise CatalogError(f"{what}: {name} must be a whole number >= 1; got {value!r}")
            values[name] = value
        elif name in ("progression_window", "baseline_trials"):
            if value is not None and (not isinstance(value, int) or isinstance(value, bool) or value < 1):
                raise CatalogError(f"{what}: {name} must be a whole number >= 1 or null; got {value!r}")
            values[name] = value
        elif name == "non_compensatory":
            if not isinstance(value, bool):
                raise CatalogError(f"{what}: non_compensatory must be true or false; got {value!r}")
            values[name] = value
        elif name == "benchmark_override":
            if not isinstance(value, str) or len(value) > 500:
                raise CatalogError(
                    f"{what}: benchmark_override must be a reason (text, at most 500 characters)"
                )
            values[name] = value
        elif name in ("rating_col", "task"):
            if value is not None and (not isinstance(value, str) or not value):
                raise CatalogError(f"{what}: {name} must be a name or null; got {value!r}")
            values[name] = value
        elif name == "alpha":
            if not isinstance(value, (int, float)) or isinstance(value, bool) or not 0 < value < 1:
                raise CatalogError(f"{what}: alpha must be a number between 0 and 1; got {value!r}")
            values[name] = float(value)
        else:
            if not isinstance(value, str) or not value:
                raise CatalogError(f"{what}: {name} must be a non-empty text; got {value!r}")
            values[name] = value
    settings = StudySettings(**values)
    _check(settings, what)
    return settings


def _check(settings: StudySettings, what: str) -> None:

    if len(settings.groups) != 2 or settings.groups[0] == settings.groups[1]:
        raise CatalogError(f"{what}: groups must name two different groups; got {list(settings.groups)!r}")
    if settings.skilled_group not in settings.groups:
        raise CatalogError(f"{what}: skilled_group {settings.skilled_group!r} is not one of the groups")
    if settings.progression_window is not None and settings.progression_window < settings.consecutive_passes:
        raise CatalogError(
            f"{what}: progression_window ({settings.progression_window}) must be at least consecutive_passes "
            f"({settings.consecutive_passes}): N passes among the last M sessions"
        )
    if settings.level not in ("participant", "trial"):
        raise CatalogError(f"{what}: level must be 'participant' or 'trial'; got {settings.level!r}")
    try:
        for names in (settings.metrics or (), settings.benchmark_metrics or ()):
            for name in names:
                REGISTRY[name]  # the error lists every known metric
        check_rule(settings.benchmark_rule)
    except MetricsError as error:
        raise CatalogError(f"{what}: {error}") from None


def settings_to_json(settings: StudySettings) -> dict:
    return {
        name: list(value) if isinstance(value, tuple) else value
        for name, value in ((n, getattr(settings, n)) for n in DECLARABLE)
    }


DEFAULT_WORDS = {
    "metrics": "the task's primary metrics (vascsim tasks show TASK)",
    "benchmark_metrics": "the analysed metrics on which experts do better (discriminating)",
    "rating_col": "the study's GRS or OSATS totals where sessions are rated, else none",
    "task": "the study's only task",
    "progression_window": "none: the passes must come in a row",
    "baseline_trials": "none: construct validity compares every practice session of both groups",
}
"""What an analysis setting left at its default (None) means, in words."""


def default_settings(table: pd.DataFrame | None) -> StudySettings:
    """For a study that declared nothing: experts against the other group, the task's primary metrics,
    the expert mean. ``table`` None: a study with no scored session yet (a declaration made before
    the data)."""
    table = pd.DataFrame({"label": []}) if table is None else table
    labels = [label for label in pd.unique(table["label"]) if label != "expert"] if "label" in table else []
    other = "trainee" if "trainee" in labels or not labels else sorted(map(str, labels))[0]
    return StudySettings(groups=("expert", other), skilled_group="expert")


def declare_analysis(
    catalog: Catalog, study_name: str, settings: StudySettings, author: str, note: str = ""
) -> int:
    """Store ``settings`` as the study's analysis; returns its version (unchanged settings add none)."""
    _check(settings, f"analysis of study {study_name!r}")
    stored = settings_to_json(settings)
    with catalog.session() as orm:
        study = catalog.study(orm, study_name)
        latest = latest_declaration(orm, study)
        if latest is not None and latest.settings == stored:
            return latest.version
        version = 1 if latest is None else latest.version + 1
        orm.add(
            AnalysisDeclaration(
                study_id=study.id,
                version=version,
                settings=stored,
                author=author,
                note=note,
                created_at=now(),
            )
        )
    return version


def declared_settings(catalog: Catalog, study_name: str, table: pd.DataFrame | None = None):
    """(settings, version, author) the study's analyses use now; defaults when none was declared."""
    with catalog.session() as orm:
        study = catalog.study(orm, study_name)
        latest = latest_declaration(orm, study)
        if latest is not None:
            what = f"declared analysis v{latest.version} of study {study_name!r}"
            return settings_from_json(latest.settings, what), latest.version, latest.author
    if table is None:
        try:
            table = CatalogStore(catalog).study_table(study_name)
        except WrongState:  # nothing scored yet: an analysis can still be declared before the data
            table = None
    return default_settings(table), None, ""


def analysis_history(catalog: Catalog, study_name: str) -> list[dict]:
    """Every declared version, oldest first: version, when, who, note, settings."""
    with catalog.session() as orm:
        study = catalog.study(orm, study_name)
        return [
            {
                "version": d.version,
                "created_at": d.created_at.isoformat(),
                "author": d.author,
                "note": d.note,
                "settings": d.settings,
            }
            for d in study.analyses
        ]


MARK_SETTINGS = (
    "group_col",
    "groups",
    "skilled_group",
    "metrics",
    "benchmark_rule",
    "benchmark_metrics",
    "benchmark_override",
)
"""Settings that change how pass marks are set: overriding one computes candidate marks for that run
instead of judging against the stored standard."""


def analyse_catalog_study(
    catalog: Catalog, study_name: str, overrides: dict[str, Any] | None = None, standard: str = "current"
) -> tuple[StudyAnalysis, AnalysisSource]:
    """The study's analysis from its declaration; ``overrides`` change it for this run only, and say so.

    ``standard``: "current" judges against the newest standard set for the analysed task
    (:mod:`sessions.scoring.standards`), its marks as stored; where none is set, or an override changes how
    marks are set, or with "candidate", marks are computed from today's data and called candidates."""
    table = CatalogStore(catalog).study_table(study_name)
    settings, version, author = declared_settings(catalog, study_name, table)
    overridden: dict[str, tuple[Any, Any]] = {}
    changes = {k: v for k, v in (overrides or {}).items() if v is not None}
    if changes:
        declared = settings_to_json(settings)
        merged = settings_from_json(
            {**declared, **settings_to_json(dataclasses.replace(settings, **changes))}, "override"
        )
        overridden = {
            k: (getattr(settings, k), getattr(merged, k))
            for k in changes
            if getattr(settings, k) != getattr(merged, k)
        }
        settings = merged
    settings, primaries = with_primary_metrics(settings, table)

    task = analysed_task(settings, table)
    stored = None
    if standard == "current" and task is not None and not set(overridden) & set(MARK_SETTINGS):
        stored = current_standard(catalog, study_name, task)
    marks = stored.benchmarks() if stored is not None else None
    analysis = analyse_study(table, settings, study_ratings(catalog, study_name), benchmarks=marks)
    analysis.standard_label = stored.label() if stored is not None else ""
    if stored is not None:
        analysis.notes.append(f"Judged against the study's {stored.label()} on {task}, its marks as set.")

        analysis = kept_verdicts(catalog, study_name, task, analysis)
        analysis.standard_drift = standard_drift(analysis, stored)
        if analysis.standard_drift:
            analysis.notes.append(
                f"Newer expert data would move {len(analysis.standard_drift)} mark(s) of the "
                f"{stored.label()} beyond the interval each had when set: "
                + "; ".join(drift_line(e) for e in analysis.standard_drift)
                + f". Consider setting a new version: `{set_command(study_name, task)}`."
            )
    elif task is not None and standard == "current" and not analysis.benchmarks.empty:
        analysis.notes.append(
            f"No standard is set for {task}: these marks are candidates computed from today's sessions "
            f"and move as sessions are added; set one with `{set_command(study_name, task)}`."
        )
    if primaries:
        analysis.notes.insert(
            0,
            f"Metrics: the task's {len(settings.metrics or ())} primary metrics (the default); declare "
            f"others with `vascsim studies analysis {shlex.quote(study_name)} --metrics ...`.",
        )
    analysis.left_out = participants_left_out(catalog, study_name, analysis)
    if analysis.left_out:
        analysis.notes.append(
            f"{len(analysis.left_out)} participant(s) of the study are not in this analysis; the report's "
            "last table says why."
        )
    stale = stale_sessions(catalog, study_name)
    if stale:
        analysis.notes.insert(
            0,
            f"{len(stale)} session(s) carry only metrics of an older registry version and are left out "
            f"(e.g. {stale[0]}); rescore them with `vascsim score --study {shlex.quote(study_name)}`.",
        )
    unverified = imported_unverified_sessions(catalog, study_name)
    if unverified:
        analysis.notes.insert(
            0,
            f"{len(unverified)} session(s) carry metric values imported from a bundle and not "
            f"recomputed here (unverified; e.g. {unverified[0]}); recompute them with "
            f"`vascsim score --study {shlex.quote(study_name)}`.",
        )
    source = (
        "declared analysis v" + str(version) if version is not None else "default analysis (none declared)"
    )
    analysis.notes.insert(0, f"Settings: the study's {source}.")
    tasks = sorted(map(str, pd.unique(table["task"])))
    if len(tasks) > 1:
        others = ", ".join(t for t in tasks if t != settings.task)
        analysis.notes.insert(
            1,
            f"Task: {settings.task} (trials count per task); the study's other task(s), {others}, "
            "are analysed on their own (--task).",
        )
    if overridden:
        analysis.notes.insert(
            1,
            "Overridden for this run only: "
            + "; ".join(f"{k} {_show(old)} -> {_show(new)}" for k, (old, new) in overridden.items())
            + ".",
        )
    return analysis, AnalysisSource(version, author, overridden)


def analysed_task(settings: StudySettings, table: pd.DataFrame) -> str | None:
    """The task an analysis of ``table`` is of: the declared one, else the table's only task; None
    when the table holds several and none is chosen (or has no task column)."""
    if settings.task is not None:
        return settings.task
    tasks = pd.unique(table["task"]) if "task" in table.columns else []
    return str(tasks[0]) if len(tasks) == 1 else None


def with_primary_metrics(settings: StudySettings, table: pd.DataFrame) -> tuple[StudySettings, bool]:
    """``settings`` with its metrics, when it declares none, set to the analysed task's primary metrics
    that the table has (:attr:`sessions.tasks.TaskSpec.primary_metrics`); and whether that was done."""

    task = analysed_task(settings, table)
    if settings.metrics is not None or "task" not in table.columns or task is None:
        return settings, False  # declared, or several tasks and none chosen (the analysis says so)
    try:
        primaries = task_spec(task).primary_metrics
    except VascsimError:  # a user's task since removed: every metric, as before
        return settings, False
    present = tuple(m for m in primaries if m in table.columns)
    if not present:
        return settings, False
    return dataclasses.replace(settings, metrics=present), True


def participants_left_out(catalog: Catalog, study_name: str, analysis: StudyAnalysis) -> list[dict]:
    """Every participant of the study absent from ``analysis``, with the reason in words."""

    settings = analysis.settings
    analysed = set(map(str, analysis.sessions[settings.cluster_col]))
    task = analysed_task(settings, analysis.sessions) or "the analysed task"
    out = []
    for person in CatalogStore(catalog).participants(study_name):
        if person.code in analysed:
            continue
        if not person.group:
            reason = "no group given"
        elif person.group not in settings.groups:
            reason = f"group '{person.group}' is not one of the two compared ({', '.join(settings.groups)})"
        elif not person.sessions:
            reason = "no session yet"
        else:
            reason = f"no scored session of {task} (under this metrics registry)"
        out.append({"participant": person.code, "group": person.group or "-", "reason": reason})
    return out


def metric_versions(catalog: Catalog, session_ids: list[int]) -> dict[int, str]:
    """Per session id: "current", "stale (vN)" (scored only by an older metric registry) or "none"."""

    with catalog.session() as orm:
        found = registry_versions(orm, session_ids)
    result = {}
    for session_id in session_ids:
        versions = found.get(session_id, set())
        if REGISTRY_VERSION in versions:
            result[session_id] = "current"
        elif versions:
            result[session_id] = f"stale (v{max(versions, key=_version_key)})"
        else:
            result[session_id] = "none"
    return result


def _version_key(version: str) -> tuple:
    return tuple(int(part) if part.isdigit() else part for part in version.split("."))


def stale_sessions(catalog: Catalog, study_name: str) -> list[str]:
    """Finished sessions of the study whose metrics come only from an older registry version."""
    with catalog.session() as orm:
        study = catalog.study(orm, study_name)
        rows = study_sessions_with(orm, study.id, SCORABLE)
    versions = metric_versions(catalog, [r[0] for r in rows])
    return [uid for session_id, uid in rows if versions[session_id].startswith("stale")]


def imported_unverified_sessions(catalog: Catalog, study_name: str) -> list[str]:
    """Sessions of the study whose current-registry metrics were imported, not computed here."""

    with catalog.session() as orm:
        study = catalog.study(orm, study_name)
        return imported_result_sessions(orm, study.id, REGISTRY_VERSION)


def _show(value: Any) -> str:
    if isinstance(value, tuple):
        return ",".join(value)
    return "all" if value is None else str(value)
