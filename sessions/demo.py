"""``vascsim demo``: a small synthetic study through the real simulator, recorder, catalog and metrics.

4 experts x 3 sessions and 6 trainees x 6 practice sessions + 1 delayed retention
session, each a scripted stitch through the vessel-wall patch in simulated time,
recorded, catalogued and scored; then construct validity on a primary metric set
declared here in advance, expert benchmarks, learning curves and the report.
"""

from __future__ import annotations

import shutil
import time
import zlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from sqlalchemy import select

from metrics.report import write_report
from metrics.study import StudyAnalysis, StudySettings
from sessions.analysis import analyse_catalog_study, declare_analysis
from sessions.catalog import Catalog, CatalogError
from sessions.models import Study
from sessions.runner import SessionPlan, run_session
from sessions.synthetic import pass_parameters, profile_for

DEMO_STUDY = "synthetic-demo"
TASK = "wall-stitch"
PRIMARY_METRICS = (
    "tip_speed_before_pierce",
    "tip_speed_after_pierce",
    "entry_angle_error_deg",
    "spectral_arc_length",
)
"""Declared before looking at data: the paper's proposed needle velocity near the insertion point, its
perpendicular-entry criterion, and smoothness of the hand (the wrist should turn the needle smoothly)."""

BENCHMARK_RULE = "percentile:75"
"""A trainee passes a metric at the level three in four experts reach (documented in docs/metrics.md)."""

DEMO_ANALYSIS = StudySettings(
    groups=("expert", "trainee"),
    skilled_group="expert",
    metrics=PRIMARY_METRICS,
    benchmark_rule=BENCHMARK_RULE,
)
"""The demo study's analysis, stored in the catalog with the study: every front-end computes from it."""


@dataclass(frozen=True)
class DemoSize:
    experts: int = 4
    expert_sessions: int = 3
    trainees: int = 6
    practice_sessions: int = 6
    retention: bool = True

    @property
    def sessions(self) -> int:
        return self.experts * self.expert_sessions + self.trainees * (self.practice_sessions + self.retention)


@dataclass
class DemoResult:
    analysis: StudyAnalysis
    report: Path
    seconds: float
    sessions: int


def _reset_study(catalog: Catalog, name: str) -> None:
    with catalog.session() as orm:
        study = orm.scalar(select(Study).where(Study.name == name))
        if study is None:
            return
        if not all(p.synthetic for p in study.participants):
            raise CatalogError(f"study {name!r} holds real participants; the demo will not replace it")
        directories = [s.directory for p in study.participants for s in p.sessions]
        orm.delete(study)
    for directory in directories:
        shutil.rmtree(directory, ignore_errors=True)


def run_demo(
    catalog: Catalog,
    home: Path,
    size: DemoSize | None = None,
    seed: int = 7,
    advance: Callable[[str], None] | None = None,
) -> DemoResult:
    """Run the whole synthetic study; ``advance`` is called after each session with its description."""
    size = size or DemoSize()
    start = time.perf_counter()
    _reset_study(catalog, DEMO_STUDY)
    plans = []
    with catalog.session() as orm:
        study = catalog.study(
            orm, DEMO_STUDY, create=True, description="Synthetic participants (vascsim demo)"
        )
        for kind, count, sessions in (
            ("expert", size.experts, size.expert_sessions),
            ("trainee", size.trainees, size.practice_sessions),
        ):
            for k in range(1, count + 1):
                code = f"{kind[0].upper()}{k:02d}"
                catalog.add_participant(orm, study, code, level=kind, group_label=kind, synthetic=True)
                profile = profile_for(
                    kind, seed * 1000 + zlib.crc32(code.encode()) % 997
                )  # not hash(): salted per process
                for trial in range(1, sessions + 1):
                    plans.append((code, trial, "practice", profile.skill(trial)))
                if kind == "trainee" and size.retention:
                    plans.append((code, sessions + 1, "retention", profile.skill(sessions, "retention")))
    for index, (code, trial, phase, skill) in enumerate(plans):
        plan = SessionPlan(DEMO_STUDY, code, TASK, trial, phase)
        run_session(catalog, home, plan, pass_parameters(skill, seed * 100_000 + index))
        if advance is not None:
            advance(f"{code} trial {trial} ({phase})")
    declare_analysis(
        catalog, DEMO_STUDY, DEMO_ANALYSIS, author="vascsim demo", note="declared before the data"
    )
    analysis, _ = analyse_catalog_study(catalog, DEMO_STUDY)
    report = write_report(analysis, home / "reports" / DEMO_STUDY, title="vascsim demo study (synthetic)")
    return DemoResult(analysis, report, time.perf_counter() - start, len(plans))
