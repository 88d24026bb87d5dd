"""A study's results as xAPI statements (IEEE 9274.1.1-2023), following cmi5 where it applies.

What each statement says (docs/interop.md has the table an LMS administrator reads):

- ``attempted``: a session was started (every session, failed ones too).
- ``completed``: its streams were finished (complete or recovered); the duration is the task's time.
- ``passed`` / ``failed``: the session judged by the study's declared proficiency rule for its task:
  ``result.score.scaled`` is the fraction of the rule's checks the session passed (each benchmarked
  metric, and in non-compensatory mode each safety check), the cmi5 ``masteryScore`` is 1.0 (every
  check must pass, so passed exactly when scaled reaches it), ``result.success`` says which.
- ``satisfied``: a trainee reached proficiency on the task (the rule's consecutive passes), once.
- ``passed`` / ``failed`` on the task's retention activity: the retention session held the level
  the trainee had reached (the study's retention rule), with the per-metric change as extensions.

The actor is a pseudonymous account: ``{homePage: <configured>, name: "<study>/<participant code>"}``;
vascsim stores no names, so none is ever sent. Every judged or completed statement carries each
scored metric as a result extension ``<base>/metrics/<name>`` = {value, unit, registry_version} in
the units a surgeon reads (metrics.units), SI's conversion done once.

A statement's id is a UUID (version 5) of the session, the kind and the statement's own content:
re-sending the same statement is idempotent at any LRS, and a statement whose content changed (a
rescore, a new benchmark) gets a new id, the old one voided by the sender (sessions.exchange.lrs).
"""

from __future__ import annotations

import hashlib
import json
import math
import uuid
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Any

import pandas as pd

from metrics.errors import MetricsError
from metrics.session.registry import REGISTRY, REGISTRY_VERSION
from metrics.units import display_unit, in_display_units
from sessions.catalog import Catalog, CatalogError
from sessions.catalog.store import CatalogStore, SessionRecord
from sessions.scoring.analysis import analyse_catalog_study
from sessions.status import SCORABLE

NAMESPACE = uuid.UUID("6f1d2c1e-5b0a-5d7e-9a43-7c9b2f0e8a11")  # vascsim's statements (uuid5 seeds)

VERBS = {
    "attempted": "http://adlnet.gov/expapi/verbs/attempted",
    "completed": "http://adlnet.gov/expapi/verbs/completed",
    "passed": "http://adlnet.gov/expapi/verbs/passed",
    "failed": "http://adlnet.gov/expapi/verbs/failed",
    "satisfied": "https://w3id.org/xapi/adl/verbs/satisfied",
    "voided": "http://adlnet.gov/expapi/verbs/voided",
}
CMI5_CATEGORY = "https://w3id.org/xapi/cmi5/context/categories/cmi5"
MOVEON_CATEGORY = "https://w3id.org/xapi/cmi5/context/categories/moveon"
CMI5_SESSION = "https://w3id.org/xapi/cmi5/context/extensions/sessionid"
CMI5_MASTERY = "https://w3id.org/xapi/cmi5/context/extensions/masteryscore"
SIMULATION = "http://adlnet.gov/expapi/activities/simulation"
MASTERY_SCORE = 1.0


class XapiError(CatalogError):
    """Statements cannot be built as asked (a bad home page or activity base)."""


@dataclass(frozen=True)
class XapiSettings:
    """home_page: the address that names this vascsim site's accounts (the actor's
    ``account.homePage``); activity_base: the IRI under which tasks, activities and extensions are
    named; language: of the display strings."""

    home_page: str
    activity_base: str = "https://vascsim.org/xapi"
    language: str = "en-US"

    def __post_init__(self) -> None:
        for name in ("home_page", "activity_base"):
            value = getattr(self, name)
            if not (isinstance(value, str) and value.startswith(("http://", "https://")) and len(value) > 8):
                raise XapiError(f"{name} must be an http(s) address; got {value!r}")


def _iso(moment: datetime) -> str:
    """An xAPI timestamp: ISO 8601 with its offset (the catalog stores UTC without one)."""
    if moment.tzinfo is None:
        moment = moment.replace(tzinfo=UTC)
    return moment.isoformat(timespec="milliseconds")


def _duration(seconds: float) -> str:
    """ISO 8601 duration to the hundredth of a second (cmi5's precision)."""
    return f"PT{max(seconds, 0.0):.2f}S"


def statement_id(key: str, body: dict[str, Any]) -> str:
    """The deterministic id: uuid5 of the statement's key and its canonical content."""
    digest = hashlib.sha256(json.dumps(body, sort_keys=True, separators=(",", ":")).encode()).hexdigest()
    return str(uuid.uuid5(NAMESPACE, f"{key}|{digest}"))


@dataclass(frozen=True)
class Statement:
    """One statement and what it is about: ``key`` (session or participant, and kind) is what the
    sender's ledger remembers it by, so a changed statement voids the one it replaces."""

    key: str
    body: dict[str, Any]

    @property
    def id(self) -> str:
        return self.body["id"]


def _finish(key: str, body: dict[str, Any]) -> Statement:
    body = {**body, "version": "1.0.3"}
    return Statement(key, {"id": statement_id(key, body), **body})


def voiding(old_id: str, actor: dict[str, Any], timestamp: str) -> Statement:
    """The statement that voids ``old_id`` (xAPI 2.2.4.5: verb voided, object a StatementRef)."""
    body = {
        "actor": actor,
        "verb": {"id": VERBS["voided"], "display": {"en-US": "voided"}},
        "object": {"objectType": "StatementRef", "id": old_id},
        "timestamp": timestamp,
        "version": "1.0.3",
    }
    return Statement(f"void|{old_id}", {"id": str(uuid.uuid5(NAMESPACE, f"void|{old_id}")), **body})


class _Builder:
    def __init__(self, study: str, settings: XapiSettings) -> None:
        self.study, self.settings = study, settings
        self.base = settings.activity_base.rstrip("/")

    def actor(self, code: str) -> dict[str, Any]:
        return {
            "objectType": "Agent",
            "account": {"homePage": self.settings.home_page, "name": f"{self.study}/{code}"},
        }

    def activity(self, task: str, suffix: str = "", title: str | None = None) -> dict[str, Any]:
        name = title or f"vascsim task {task}" + (f", {suffix}" if suffix else "")
        return {
            "objectType": "Activity",
            "id": f"{self.base}/tasks/{task}" + (f"/{suffix}" if suffix else ""),
            "definition": {"name": {self.settings.language: name}, "type": SIMULATION},
        }

    def verb(self, kind: str) -> dict[str, Any]:
        return {"id": VERBS[kind], "display": {"en-US": kind}}

    def context(self, code: str, task: str, session: str | None, cmi5: bool, moveon: bool) -> dict:
        registration = str(uuid.uuid5(NAMESPACE, f"registration|{self.study}|{code}|{task}"))
        context: dict[str, Any] = {
            "registration": registration,
            "contextActivities": {
                "grouping": [{"objectType": "Activity", "id": f"{self.base}/studies/{self.study}"}]
            },
            "extensions": {f"{self.base}/extensions/registry-version": REGISTRY_VERSION},
        }
        if session is not None:
            context["extensions"][CMI5_SESSION] = session
        if cmi5:
            categories = [{"id": CMI5_CATEGORY}] + ([{"id": MOVEON_CATEGORY}] if moveon else [])
            context["contextActivities"]["category"] = categories
        return context

    def metric_extensions(self, values: dict[str, float]) -> dict[str, Any]:
        out = {}
        for name, value in sorted(values.items()):
            if name not in REGISTRY or value is None or pd.isna(value) or not math.isfinite(float(value)):
                continue
            unit = REGISTRY[name].unit
            out[f"{self.base}/metrics/{name}"] = {
                "value": round(float(in_display_units(float(value), unit)), 6),
                "unit": display_unit(unit) or "1",
                "registry_version": REGISTRY_VERSION,
            }
        return out


def _session_rows(catalog: Catalog, study_name: str) -> list[SessionRecord]:
    """The study's sessions by participant, task and trial (:meth:`CatalogStore.sessions`)."""
    rows = CatalogStore(catalog).sessions(study_name)
    return sorted(rows, key=lambda r: (r.participant, r.task, r.trial))


def _analyses(catalog: Catalog, study_name: str, tasks: list[str]) -> dict[str, Any]:
    """The declared analysis of each task that can be analysed (a task without one: no judgement)."""
    found = {}
    for task in tasks:
        try:
            found[task], _ = analyse_catalog_study(catalog, study_name, {"task": task})
        except (MetricsError, CatalogError):
            continue
    return found


def study_statements(catalog: Catalog, study_name: str, settings: XapiSettings) -> list[Statement]:
    """Every statement the study's sessions and trainees give today, in time order."""
    rows = _session_rows(catalog, study_name)
    scored = {r.task for r in rows if r.status in SCORABLE}
    analyses = _analyses(catalog, study_name, sorted(scored))
    build = _Builder(study_name, settings)
    statements: list[Statement] = []
    by_session: dict[str, dict[str, Any]] = {}
    for analysis in analyses.values():
        metrics = analysis.sessions.set_index("session_id")
        judged = analysis.proficiency.set_index("session_id")
        checks = [c for c in judged.columns if c.startswith(("pass_", "safety_"))]
        for uid in judged.index:
            values = {c: metrics.at[uid, c] for c in metrics.columns if c in REGISTRY}
            outcome = judged.loc[uid, checks]
            measured = outcome[outcome.notna()].astype(bool)  # a metric with no value is no check
            by_session[uid] = {
                "values": values,
                "passed": bool(judged.at[uid, "passed"]),
                "raw": int(measured.sum()),
                "checks": int(measured.size),
            }
    ended: dict[tuple[str, str, int], datetime] = {}
    for row in rows:
        start = _iso(row.started_at)
        actor = build.actor(row.participant)
        statements.append(
            _finish(
                f"{row.uid}|attempted",
                {
                    "actor": actor,
                    "verb": build.verb("attempted"),
                    "object": build.activity(row.task),
                    "context": build.context(row.participant, row.task, row.uid, cmi5=False, moveon=False),
                    "timestamp": start,
                },
            )
        )
        if row.status not in SCORABLE:
            continue
        end = row.ended_at or row.started_at
        ended[(row.participant, row.task, row.trial)] = end
        judged = by_session.get(row.uid)
        values = judged["values"] if judged else {}
        task_time = values.get("task_time")
        seconds = (
            float(task_time)
            if task_time is not None and math.isfinite(float(task_time))
            else (end - row.started_at).total_seconds()
        )
        extensions = build.metric_extensions(values)
        completed = {"completion": True, "duration": _duration(seconds)}
        if extensions:
            completed["extensions"] = extensions
        statements.append(
            _finish(
                f"{row.uid}|completed",
                {
                    "actor": actor,
                    "verb": build.verb("completed"),
                    "object": build.activity(row.task),
                    "result": completed,
                    "context": build.context(row.participant, row.task, row.uid, cmi5=True, moveon=True),
                    "timestamp": _iso(end),
                },
            )
        )
        if judged is None or judged["checks"] == 0:
            continue
        kind = "passed" if judged["passed"] else "failed"
        scaled = judged["raw"] / judged["checks"]
        context = build.context(row.participant, row.task, row.uid, cmi5=True, moveon=True)
        context["extensions"][CMI5_MASTERY] = MASTERY_SCORE
        context["extensions"][f"{build.base}/extensions/phase"] = row.phase
        context["extensions"][f"{build.base}/extensions/trial"] = int(row.trial)
        statements.append(
            _finish(
                f"{row.uid}|judged",
                {
                    "actor": actor,
                    "verb": build.verb(kind),
                    "object": build.activity(row.task),
                    "result": {
                        "success": judged["passed"],
                        "score": {
                            "scaled": round(scaled, 6),
                            "raw": judged["raw"],
                            "min": 0,
                            "max": judged["checks"],
                        },
                        "duration": _duration(seconds),
                        **({"extensions": extensions} if extensions else {}),
                    },
                    "context": context,
                    "timestamp": _iso(end),
                },
            )
        )
    for task, analysis in analyses.items():
        statements += _trainee_statements(build, task, analysis, ended)
    return sorted(statements, key=lambda s: (s.body["timestamp"], s.key))


def _trainee_statements(
    build: _Builder, task: str, analysis: Any, ended: dict[tuple[str, str, int], datetime]
) -> list[Statement]:
    out = []
    last_practice = analysis.sessions[analysis.sessions["phase"].fillna("practice") != "retention"]
    for row in analysis.trainees.itertuples():
        code = str(row.participant_id)
        actor = build.actor(code)
        if bool(row.proficient) and not pd.isna(row.trials_to_proficiency):
            trial = int(row.trials_to_proficiency)
            when = ended.get((code, task, trial))
            if when is None:
                continue
            context = build.context(code, task, None, cmi5=True, moveon=False)
            context["extensions"][CMI5_MASTERY] = MASTERY_SCORE
            out.append(
                _finish(
                    f"{build.study}|{code}|{task}|proficient",
                    {
                        "actor": actor,
                        "verb": build.verb("satisfied"),
                        "object": build.activity(task),
                        "result": {
                            "success": True,
                            "completion": True,
                            "extensions": {f"{build.base}/extensions/trials-to-proficiency": trial},
                        },
                        "context": context,
                        "timestamp": _iso(when),
                    },
                )
            )
        retained = getattr(row, "retention_passed", None)
        if retained is None or pd.isna(retained):
            continue
        mine = analysis.sessions[analysis.sessions["participant_id"] == row.participant_id]
        delayed = mine[mine["phase"] == "retention"]
        if delayed.empty:
            continue
        trial = int(delayed["trial"].iloc[-1])
        when = ended.get((code, task, trial))
        if when is None:
            continue
        changes = {
            f"{build.base}/retention-change/{name[len('retention_change_') :]}": _change(
                getattr(row, name), name[len("retention_change_") :]
            )
            for name in analysis.trainees.columns
            if name.startswith("retention_change_")
        }
        changes = {k: v for k, v in changes.items() if v is not None}
        practice = int((last_practice["participant_id"] == row.participant_id).sum())
        out.append(
            _finish(
                f"{build.study}|{code}|{task}|retention",
                {
                    "actor": actor,
                    "verb": build.verb("passed" if bool(retained) else "failed"),
                    "object": build.activity(task, "retention", f"vascsim task {task}, retention"),
                    "result": {
                        "success": bool(retained),
                        "extensions": {**changes, f"{build.base}/extensions/practice-sessions": practice},
                    },
                    "context": build.context(code, task, str(delayed["session_id"].iloc[-1]), False, False),
                    "timestamp": _iso(when),
                },
            )
        )
    return out


def _change(value: Any, metric: str) -> dict[str, Any] | None:
    """A retention change (retention minus practice, SI) in display units, with its unit."""
    if value is None or pd.isna(value) or metric not in REGISTRY:
        return None
    unit = REGISTRY[metric].unit
    return {"value": round(float(in_display_units(float(value), unit)), 6), "unit": display_unit(unit) or "1"}
