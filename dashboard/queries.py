"""What each page shows, as plain dictionaries, always filtered by who is asking.

The catalog store's scoped reads (:mod:`sessions.catalog.views`) answer every lookup, so an id that
exists but belongs to somebody else answers exactly like an id that does not exist; this module only
composes them with the study's analysis. It holds no query of its own.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from dashboard.analysis import AnalysisCache, benchmark_rows, records, roc_points
from dashboard.auth import Viewer
from metrics.reading.feedback import metric_groups, participant_feedback, session_feedback
from metrics.reading.tables import (
    composite_summary,
    concurrent_for_reading,
    display_scale,
    participant_medians,
    reliability_tables,
    standards_tables,
    summary_in_display_units,
    table_text,
)
from metrics.replay.reference import SIGNALS
from metrics.session.registry import REGISTRY, REGISTRY_VERSION
from metrics.study.analysis import practice_mask
from metrics.study.proficiency import benchmarks_heading, drift_line
from metrics.units import display_unit, in_display_units
from recorder.layout import SAMPLES_JOURNAL
from sessions.catalog.store import CatalogStore, ParticipantRecord, SessionRecord
from sessions.scoring.analysis import analysed_task
from sessions.scoring.review import against_band, expert_band, session_stitches
from sessions.scoring.standards import set_command
from sessions.status import SCORABLE
from sessions.tasks import known_task, task_spec
from sim.errors import VascsimError

ATTENTION_AFTER_TRIALS = 5
"""A trainee not yet proficient after this many practice sessions needs a supervisor's look."""


def studies(store: CatalogStore, viewer: Viewer) -> list[dict]:
    return [
        {
            "id": r.id,
            "name": r.name,
            "description": r.description,
            "participants": r.participants,
            "sessions": r.sessions,
        }
        for r in store.studies(viewer)
    ]


def _participant_row(record: ParticipantRecord, viewer: Viewer) -> dict:
    row = {
        "id": record.id,
        "code": record.code,
        "group": record.group,
        "synthetic": record.synthetic,
        "sessions": record.sessions,
        "last_session_at": record.last_session_at,
    }
    if viewer.sees_accounts:
        row["account"] = record.account
    return row


def study_overview(store: CatalogStore, analyses: AnalysisCache, viewer: Viewer, study_id: int) -> dict:
    """Participants, their latest score against the benchmark, and who needs attention."""
    study = store.study(study_id, viewer, whole=True)
    statuses = store.sessions_by_status(study_id, viewer)
    participants = [_participant_row(r, viewer) for r in store.study_participants(study_id, viewer)]
    info = study.as_dict()
    overview = {"study": info, "sessions_by_status": statuses, "participants": participants}
    scored = sum(statuses.get(s, 0) for s in SCORABLE)
    if not scored:
        overview.update(benchmarks=[], attention=[], synthetic=False)
        return overview
    cached = analyses.get(study_id)
    analysis = cached.analysis
    latest = _latest_scores(analysis)
    trainees = analysis.trainees.set_index("participant_id") if not analysis.trainees.empty else None
    if analysis.benchmarks.empty:  # no standard: nobody is worse than a mark that does not exist
        trainees = None
        for scores in latest.values():
            scores.update(latest_passed=None, passes=None)
    attention = []
    for row in participants:
        row.update(latest.get(row["code"], {}))
        reasons = _attention_reasons(row, trainees)
        row["attention"] = reasons
        if reasons:
            attention.append({"participant_id": row["id"], "code": row["code"], "reasons": reasons})
    task = analysed_task(analysis.settings, analysis.sessions)
    overview.update(
        task=task,
        benchmarks=benchmark_rows(analysis),
        benchmark_heading=benchmarks_heading(
            analysis.benchmarks, analysis.settings.min_experts, analysis.standard_label
        ),
        attention=attention,
        synthetic=analysis.synthetic,
        drift=[drift_line(entry) for entry in analysis.standard_drift],
        set_command=set_command(info["name"], task) if task else "",
    )
    return overview


def _latest_scores(analysis) -> dict[str, dict]:
    table, passed = analysis.sessions, analysis.proficiency["passed"]
    latest = {}
    for code, rows in table.groupby("participant_id", sort=False):
        last = rows.index[-1]
        latest[code] = {
            "latest_session": table.at[last, "session_id"],
            "latest_trial": int(table.at[last, "trial"]),
            "latest_phase": str(table.at[last, "phase"] or "practice"),
            "latest_passed": bool(passed.loc[last]),
            "passes": int(passed.loc[rows.index].sum()),
        }
    return latest


def _attention_reasons(row: dict, trainees: pd.DataFrame | None) -> list[str]:
    if trainees is None or row["code"] not in trainees.index:
        return []
    record = trainees.loc[row["code"]]
    reasons = []
    row["proficient"] = bool(record["proficient"])
    trials = record.get("trials_to_proficiency")
    known = trials is not None and trials == trials  # NaN: not reached
    row["proficient_at"] = int(trials) if row["proficient"] and known else None
    if not row["proficient"] and int(record["practice_sessions"]) >= ATTENTION_AFTER_TRIALS:
        reasons.append(f"not proficient after {int(record['practice_sessions'])} practice sessions")
    kept = record["retention_passed"] if "retention_passed" in record.index else None
    retention = kept is not None and not pd.isna(kept) and not bool(kept)  # numpy's False is not False
    if retention:
        reasons.append("the delayed retention session was worse than the benchmark")
    latest_practice = row.get("latest_phase", "practice") != "retention"
    if row.get("latest_passed") is False and "latest_trial" in row and latest_practice:
        trial = row["latest_trial"]
        reasons.append(f"the latest practice session (trial {trial}) was worse than the benchmark")
    return reasons


def participant_progress(
    store: CatalogStore, analyses: AnalysisCache, viewer: Viewer, participant_id: int
) -> dict:
    """Learning curve per benchmarked metric with the benchmark line, pass/fail history, retention."""
    participant = store.participant(participant_id, viewer)
    sessions = store.participant_sessions(participant_id, viewer)
    study_id = participant.study_id
    info = {
        "id": participant.id,
        "code": participant.code,
        "group": participant.group,
        "synthetic": participant.synthetic,
        "study": {"id": study_id, "name": participant.study},
    }
    progress = {
        "participant": info,
        "sessions": [
            {
                "uid": r.uid,
                "task": r.task,
                "trial": r.trial,
                "phase": r.phase,
                "status": r.status,
                "started_at": r.started_at,
            }
            for r in sessions
        ],
        "curves": [],
        "benchmarks": [],
        "trainee": None,
        "feedback": None,
    }
    if not any(s["status"] in SCORABLE for s in progress["sessions"]):
        return progress
    analysis = analyses.get(study_id).analysis
    mine = analysis.sessions["participant_id"] == info["code"]
    rows = analysis.sessions[mine]
    passed = analysis.proficiency.loc[rows.index, "passed"]
    for item in progress["sessions"]:
        hit = rows.index[rows["session_id"] == item["uid"]]
        item["passed"] = bool(passed.loc[hit[0]]) if len(hit) else None
    for bench in analysis.benchmarks.itertuples():
        unit = REGISTRY[bench.metric].unit if bench.metric in REGISTRY else ""
        progress["curves"].append(
            {  # in the units a surgeon reads (metrics.units), each point with its own pass/fail
                "metric": bench.metric,
                "unit": display_unit(unit),
                "better": bench.better,
                "benchmark": in_display_units(bench.benchmark, unit),
                "trial": rows["trial"].tolist(),
                "phase": rows["phase"].fillna("practice").tolist(),
                "passed": [bool(p) for p in passed],
                "value": [in_display_units(v, unit) for v in rows[bench.metric].astype(float)],
            }
        )
    progress["benchmarks"] = benchmark_rows(analysis)
    if not analysis.trainees.empty and info["code"] in set(analysis.trainees["participant_id"]):
        found = analysis.trainees[analysis.trainees["participant_id"] == info["code"]]
        progress["trainee"] = records(found)[0]
        progress["feedback"] = participant_feedback(analysis, info["code"])
        progress["feedback"]["task"] = analysis.settings.task
    return progress


def _task_benchmarks(analyses: AnalysisCache, study_id: int, task: str) -> pd.DataFrame | None:
    """The study's benchmarks when its declared analysis is of ``task`` (what the session is judged
    against, as the station and `vascsim sessions show` judge it); None when it has none for it."""
    try:
        analysis = analyses.get(study_id).analysis
    except VascsimError:  # nothing analysable yet
        return None
    return analysis.benchmarks if analysed_task(analysis.settings, analysis.sessions) == task else None


def session_detail(store: CatalogStore, analyses: AnalysisCache, viewer: Viewer, uid: str) -> dict:
    """A session, its metrics against the expert band (quartiles of expert sessions), events and files."""
    facts = store.session_facts(uid, viewer)
    row = facts.session
    detail = {
        "uid": row.uid,
        "status": row.status,
        "trial": row.trial,
        "phase": row.phase,
        "device": row.device,
        "clock": facts.clock,
        "task": row.task,
        "started_at": row.started_at,
        "ended_at": row.ended_at,
        "error": facts.error,
        "participant": {"id": facts.participant_id, "code": row.participant, "group": facts.group},
        "synthetic": facts.synthetic,
        "study": {"id": facts.study_id, "name": row.study},
        "files": [f.as_dict() for f in facts.files],
        "annotations": [a.as_dict() for a in facts.annotations],
    }
    values = facts.metrics
    study_id, task_id, catalog = facts.study_id, facts.task_id, store.catalog
    band = analyses.derived(
        study_id, f"expert-band-{task_id}", lambda: expert_band(catalog, study_id, task_id)
    )
    detail["metrics"] = against_band(values, band)
    detail["signal_bands"] = signal_bands(detail["metrics"])
    marks = _task_benchmarks(analyses, study_id, detail["task"]) if row.status in SCORABLE else None
    detail.update(
        session_feedback(detail["metrics"], benchmarks=marks), metric_groups=metric_groups(detail["metrics"])
    )
    detail["stitches"] = session_stitches(catalog, uid)
    detail["target_bite_m"] = target_bite(detail["task"])
    return detail


def target_bite(task: str) -> float | None:
    """The task's target bite from the wound edge (m), if the task library declares one."""

    placement = task_spec(task).placement if known_task(task) else None
    return None if placement is None else float(placement["target_bite_m"])


def validity_report(store: CatalogStore, analyses: AnalysisCache, viewer: Viewer, study_id: int) -> dict:
    """The construct-validity table, per-participant values for box plots, and ROC curves."""
    study = store.study(study_id, viewer, whole=True)
    info = {"id": study.id, "name": study.name}
    analysis = analyses.get(study_id).analysis
    settings = analysis.settings
    table = summary_in_display_units(analysis)
    metrics = table["metric"].tolist()
    medians = participant_medians(analysis, metrics)
    skilled = (medians[settings.group_col] == settings.skilled_group).to_numpy()
    scales = {metric: display_scale(metric) for metric in metrics}  # the units a surgeon reads
    boxes = {
        metric: {
            group: [
                scales[metric][0] * float(v)
                for v in medians.loc[medians[settings.group_col] == group, metric].dropna()
            ]
            for group in settings.groups
        }
        for metric in metrics
    }
    practice = analysis.sessions[practice_mask(analysis.sessions)]
    retest, consistency, raters = reliability_tables(analysis)  # the report's own tables
    return {
        "standards": {
            "notes": analysis.standards.notes if analysis.standards else [],
            "rule": settings.benchmark_rule,
            "tables": {name: _shown(frame) for name, frame in standards_tables(analysis).items()},
        },
        "reliability": {
            "notes": analysis.reliability.notes if analysis.reliability else [],
            "retest": _shown(retest),
            "consistency": consistency,
            "raters": [{"instrument": name, "table": _shown(frame)} for name, frame in raters],
        },
        "study": info,
        "groups": list(settings.groups),
        "level": analysis.validity.level,
        "n_participants": {str(k): int(v) for k, v in analysis.validity.n_participants.items()},
        "n_sessions": {str(k): int(v) for k, v in analysis.validity.n_sessions.items()},
        "left_out": list(analysis.left_out),  # every participant not counted above, and why
        "practice_sessions": len(practice),
        "table": records(table),
        "notes": list(analysis.validity.notes) + list(analysis.notes),
        "composite": composite_summary(analysis.validity.composite),
        "concurrent": None
        if analysis.concurrent is None
        else {
            "rating": analysis.concurrent.rating_col,
            "table": _shown(concurrent_for_reading(analysis.concurrent.table)),
            "notes": analysis.concurrent.notes,
        },
        "skilled_group": settings.skilled_group,
        "synthetic": analysis.synthetic,
        "boxes": boxes,
        "box_axes": {metric: label for metric, (_, label) in scales.items()},
        "roc": [c for c in (roc_points(medians, m, skilled) for m in metrics) if c is not None],
        "registry_version": REGISTRY_VERSION,
    }


def _shown(frame: pd.DataFrame) -> dict:
    """A table as the page shows it: its column names and rows of display text."""

    return {
        "columns": [str(c) for c in frame.columns],
        "rows": [[table_text(v) for v in row] for row in frame.itertuples(index=False)],
    }


def session_list(store: CatalogStore, viewer: Viewer, study_id: int | None, limit: int, offset: int) -> dict:
    """Sessions the viewer may see, newest first."""
    total, rows = store.visible_sessions(viewer, study_id, limit, offset)
    items = [
        {
            "uid": r.uid,
            "status": r.status,
            "trial": r.trial,
            "phase": r.phase,
            "started_at": r.started_at,
            "participant": r.participant,
        }
        for r in rows
    ]
    return {"total": total, "items": items}


SIGNAL_BANDS = {"force": ("peak_force", "experts' peak force, middle half")}
"""Signal plot -> (the metric whose expert band is drawn on it, the band's label)."""


def signal_bands(rows: list[dict]) -> dict:
    """The experts' interquartile band of each plotted signal's metric, in the plot's unit."""

    by_metric = {row["metric"]: row for row in rows}
    bands = {}
    for signal, (metric, label) in SIGNAL_BANDS.items():
        row = by_metric.get(metric)
        if row is None or row["expert_q1"] is None or row["expert_q3"] is None:
            continue
        factor = SIGNALS[signal][1]
        bands[signal] = {"low": factor * row["expert_q1"], "high": factor * row["expert_q3"], "label": label}
    return bands


def recording_now(store: CatalogStore, ingest_root: Path) -> dict:
    """Sessions recording now: local ones (catalog status running, newest first) and the remote
    stations streaming to the ingest (a samples journal under ``ingest_root/STATION/SESSION``)."""
    running: list[SessionRecord] = store.running_sessions()
    stations = []
    if ingest_root.is_dir():
        for journal in sorted(ingest_root.glob(f"*/*/{SAMPLES_JOURNAL}")):
            stations.append({"station": journal.parent.parent.name, "session": journal.parent.name})
    return {
        "sessions": [
            {"uid": r.uid, "participant": r.participant, "started_at": r.started_at} for r in running
        ],
        "stations": stations,
    }
