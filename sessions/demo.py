"""``vascsim demo``: a small synthetic course through the real simulator, recorder, catalog and metrics.

A two-task curriculum on a porcine artery with an arteriotomy (docs/tasks.md): 5 experts x 2
sessions and 6 trainees x 8 practice sessions + 1 delayed retention session of the
interrupted stitch (the last trainee a slow learner), then every participant closes the
arteriotomy with a row of three stitches (the course's final task). Each session is scripted
through the simulator in simulated time, recorded, catalogued and scored; then, per task
(trials count per task), construct validity on a primary metric set declared here in advance,
the standard set once the experts are recorded, learning curves and the report.
"""

from __future__ import annotations

import dataclasses
import multiprocessing
import os
import shutil
import time
import zlib
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from metrics.instruments import GRS
from metrics.reading.report import write_report
from metrics.study.analysis import StudyAnalysis, StudySettings
from sessions.catalog import Catalog, CatalogError, WrongState
from sessions.catalog.lookups import study_named, study_session_keys
from sessions.config import cache_dir
from sessions.running.runner import SessionPlan, run_session
from sessions.scoring.analysis import analyse_catalog_study, declare_analysis
from sessions.scoring.ratings import checked_rating, store_ratings
from sessions.scoring.setting import set_standard
from sessions.synthetic import profile_for, scripted_hands
from sessions.tasks import task_spec, tissue_for

DEMO_STUDY = "synthetic-demo"
TASK = "interrupted-stitch"
"""The practice task: the course's entry-level stitch, analysed with learning curves and retention."""
FINAL_TASK = "arteriotomy-closure"
"""The course's final task: each participant closes the arteriotomy once, after practice."""
PRIMARY_METRICS = task_spec(TASK).primary_metrics
"""Declared before looking at data: the task's primary metrics (sessions.tasks.TaskSpec.primary_metrics)."""

BENCHMARK_METRICS = tuple(m for m in PRIMARY_METRICS if m != "spectral_arc_length")
"""Declared before the data: pass marks on the source paper's proposed measures (the tip's speed near
the insertion point, before and after the pierce; a perpendicular entry) and on where the bite went.
Smoothness (SPARC) is validated but sets no mark: over a whole session it moves with the session's
length and phases (a slow, careful insertion reads as less smooth), too much to fail a stitch on."""

BENCHMARK_RULE = "mean+sd:2"
"""A trainee passes a metric within two standard deviations of the experts' mean on the worse side
(Lap Mentor's "expert mean + 2 SD"; docs/metrics.md): a mark the experts themselves meet most of
the time, so that passing every benchmark in one session is within an expert's reach."""

BASELINE_TRIALS = 2
"""Construct validity compares the experts with each trainee's first two practice sessions: a trainee
who practises to the experts' level stops differing from them, which is the course working, not the
metric failing."""

DEMO_ANALYSIS = StudySettings(
    groups=("expert", "trainee"),
    skilled_group="expert",
    metrics=PRIMARY_METRICS,
    benchmark_rule=BENCHMARK_RULE,
    benchmark_metrics=BENCHMARK_METRICS,
    baseline_trials=BASELINE_TRIALS,
    task=TASK,
)
"""The demo study's analysis, stored in the catalog with the study: every front-end computes from it."""


@dataclass(frozen=True)
class DemoSize:
    experts: int = 5  # the rule's minimum for a standard that is not provisional
    expert_sessions: int = 2
    trainees: int = 6  # the last one a slow learner (when there are at least 4)
    practice_sessions: int = 8
    retention: bool = True
    closures: bool = True  # each participant closes the arteriotomy once, after practice
    ratings: bool = True  # two synthetic raters score every session with the GRS
    benchmark_override: str = ""
    """A reason to benchmark the declared metrics where experts do better though the design is too small
    for an AUC interval (test fixtures of two experts and three trainees); printed in every report."""

    @property
    def sessions(self) -> int:
        practice = self.experts * self.expert_sessions + self.trainees * (
            self.practice_sessions + self.retention
        )
        return practice + (self.experts + self.trainees) * self.closures


@dataclass
class DemoResult:
    analysis: StudyAnalysis
    report: Path
    seconds: float
    sessions: int
    final: StudyAnalysis | None = None  # the final task's analysis (None without closures)
    final_report: Path | None = None
    relinked: tuple[str, ...] = ()  # codes whose trainee accounts were linked again after a re-run
    unlinked: tuple[str, ...] = ()  # codes with an account that the new demo no longer has
    videos_removed: int = 0  # replay videos of the previous demo's sessions, deleted with them


@dataclass(frozen=True)
class PreviousDemo:
    """What a re-run keeps from the demo it replaces: each participant code's linked account."""

    links: dict[str, int]
    videos_removed: int


SYNTHETIC_RATERS = (("synthetic rater A", 0.0), ("synthetic rater B", -0.4))
"""The demo's raters and their leniency (B scores 0.4 points lower on every item): synthetic, and named so."""


def synthetic_ratings(catalog: Catalog, runs: list, seed: int) -> int:
    """Each session scored with the GRS by the two synthetic raters: every item is the session's
    motion skill on the 1-5 scale (1 + 4 x skill) plus the rater's leniency and the rater's own noise
    (SD 0.6 per item), rounded and kept within 1-5. Stored as any rating is (checked against the
    instrument); returns how many ratings."""

    with catalog.session() as orm:
        rows = study_session_keys(orm, DEMO_STUDY)
    uids = {(code, task, trial, phase): uid for uid, code, task, trial, phase in rows}
    rng = np.random.default_rng(seed)
    ratings = []
    for plan, skills, _ in runs:
        uid = uids.get((plan.participant, plan.task, plan.trial, plan.phase))
        if uid is None:
            continue
        for rater, leniency in SYNTHETIC_RATERS:
            level = 1.0 + 4.0 * skills[0] + leniency
            scores = {
                item: int(np.clip(round(level + rng.normal(0.0, 0.6)), GRS.low, GRS.high))
                for item in GRS.item_names
            }
            ratings.append(checked_rating(uid, rater, GRS.name, scores))
    return store_ratings(catalog, ratings)


def _reset_study(catalog: Catalog, name: str, home: Path) -> PreviousDemo:
    """Delete the previous demo study, its recordings and its replay videos (which would otherwise
    outlive their sessions); return the trainee accounts linked to its participants, by code."""
    with catalog.session() as orm:
        study = study_named(orm, name)
        if study is None:
            return PreviousDemo({}, 0)
        if not all(p.synthetic for p in study.participants):
            raise CatalogError(f"study {name!r} holds real participants; the demo will not replace it")
        links = {p.code: p.user_id for p in study.participants if p.user_id is not None}
        sessions = [(s.uid, s.directory) for p in study.participants for s in p.sessions]
        orm.delete(study)
    for _, directory in sessions:
        shutil.rmtree(directory, ignore_errors=True)
    videos = [v for uid, _ in sessions for v in (home / "replays").glob(f"{uid}*.mp4")]
    for video in videos:
        video.unlink(missing_ok=True)
    return PreviousDemo(links, len(videos))


_WORKER_CATALOGS: dict[str, Catalog] = {}


def _skills(profile, trial: int, phase: str = "practice") -> tuple[float, float]:
    """(motion skill, placement skill) of a synthetic participant at a trial."""
    return profile.skill(trial, phase), profile.placement_skill(trial, phase)


def _run_planned(url: str, home: str, plan: SessionPlan, skills: tuple, seed: int) -> SessionPlan:
    """One demo session in a worker process (its own catalog connection, opened once)."""
    if url not in _WORKER_CATALOGS:
        _WORKER_CATALOGS[url] = Catalog(url, migrate=False)
    run_session(_WORKER_CATALOGS[url], Path(home), plan, scripted_hands(skills[0], seed, skills[1]))
    return plan


ONE_THREAD = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
"""The demo's worker processes run their numerical libraries on one thread each: with one worker per
core, CHOLMOD's OpenMP threads and OpenBLAS's own in each worker would oversubscribe the cores
(measured on 2 cores: the demo 141 s with them, 100 s without; docs/benchmarks.md)."""


def one_thread_each() -> None:
    """A worker process's initializer: one thread per numerical library, for those loaded from now on
    (the environment they read as they load: CHOLMOD's OpenMP) and those already loaded (NumPy's
    OpenBLAS, which the worker's first import brought in)."""
    from threadpoolctl import threadpool_limits

    os.environ.update(ONE_THREAD)
    threadpool_limits(1)


def _run_all(catalog: Catalog, home: Path, runs: list, workers: int) -> Iterator[SessionPlan]:
    """Run the sessions, ``workers`` at a time (each session is one process's simulation: they are
    independent, their trials are fixed in advance and the catalog takes concurrent writers);
    yields each plan as its session is stored."""
    if workers <= 1:
        for plan, skills, session_seed in runs:
            run_session(catalog, home, plan, scripted_hands(skills[0], session_seed, skills[1]))
            yield plan
        return
    context = multiprocessing.get_context("spawn")  # no inherited database connections or threads
    # the longest first (a closure's three stitches before the single ones), so no worker is left
    # with a long session while the other has nothing to do; each session's seed is its own
    ordered = sorted(runs, key=lambda run: -len(task_spec(run[0].task).bites()))
    with ProcessPoolExecutor(workers, mp_context=context, initializer=one_thread_each) as pool:
        pending = [pool.submit(_run_planned, catalog.url, str(home), *run) for run in ordered]
        try:
            for done in as_completed(pending):
                yield done.result()
        except BaseException:
            for future in pending:
                future.cancel()
            raise


def run_demo(
    catalog: Catalog,
    home: Path,
    size: DemoSize | None = None,
    seed: int = 7,
    advance: Callable[[str], None] | None = None,
    workers: int | None = None,
) -> DemoResult:
    """Run the whole synthetic study; ``advance`` is called after each session with its description.
    ``workers``: sessions run at once (default: one per core, at most 2)."""
    workers = workers if workers is not None else min(2, os.cpu_count() or 1)
    size = size or DemoSize()
    start = time.perf_counter()
    previous = _reset_study(catalog, DEMO_STUDY, home)
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
                participant = catalog.add_participant(
                    orm, study, code, level=kind, group_label=kind, synthetic=True
                )
                participant.user_id = previous.links.get(code)  # a re-run keeps trainee accounts linked
                slow = kind == "trainee" and k == count >= 4  # one who does not get there
                profile = profile_for(
                    kind, seed * 1000 + zlib.crc32(code.encode()) % 997, slow_learner=slow
                )  # not hash(): salted per process
                for trial in range(1, sessions + 1):
                    plans.append((code, TASK, trial, "practice", _skills(profile, trial)))
                if size.closures:  # the final task, with what the practice on the other carries over
                    plans.append((code, FINAL_TASK, 1, "practice", profile.transferred(sessions)))
                if kind == "trainee" and size.retention:
                    retained = _skills(profile, sessions, "retention")
                    plans.append((code, TASK, sessions + 1, "retention", retained))
        for name in {task for _, task, *_ in plans}:  # the rows the workers' sessions point at
            spec = task_spec(name)
            catalog.task(orm, spec.name, spec.scenario, spec.parameters.as_dict())
    for name in {task for _, task, *_ in plans}:
        tissue_for(task_spec(name), cache_dir(home))  # precomputed once, on disk, before the workers load it
    runs = [
        (SessionPlan(DEMO_STUDY, code, task, trial, phase), skills, seed * 100_000 + index)
        for index, (code, task, trial, phase, skills) in enumerate(plans)
    ]
    for plan in _run_all(catalog, home, runs, workers):
        if advance is not None:
            advance(f"{plan.participant} {plan.task} trial {plan.trial} ({plan.phase})")
    if size.ratings:
        synthetic_ratings(catalog, runs, seed)
    declared = DEMO_ANALYSIS
    if size.benchmark_override:
        declared = dataclasses.replace(DEMO_ANALYSIS, benchmark_override=size.benchmark_override)
    declare_analysis(catalog, DEMO_STUDY, declared, author="vascsim demo", note="declared before the data")
    try:  # a course sets its standard once its experts are recorded; the demo does the same
        set_standard(catalog, DEMO_STUDY, TASK, "vascsim demo", "set once the experts were recorded")
    except WrongState:
        pass  # no metric qualifies (a design too small): the report says there is no standard and why
    analysis, _ = analyse_catalog_study(catalog, DEMO_STUDY)
    reports = home / "reports" / DEMO_STUDY
    report = write_report(analysis, reports, title=f"vascsim demo study (synthetic): {TASK}")
    final = final_report = None
    if size.closures:
        final, _ = analyse_catalog_study(catalog, DEMO_STUDY, {"task": FINAL_TASK})
        final_report = write_report(
            final, reports / FINAL_TASK, title=f"vascsim demo study (synthetic): {FINAL_TASK}"
        )
    codes = {code for code, *_ in plans}
    return DemoResult(
        analysis,
        report,
        time.perf_counter() - start,
        len(plans),
        final,
        final_report,
        relinked=tuple(sorted(set(previous.links) & codes)),
        unlinked=tuple(sorted(set(previous.links) - codes)),
        videos_removed=previous.videos_removed,
    )
