"""Synthetic participants: scripted suturing passes whose skill parameters differ by profile.

Every synthetic participant is stored with ``synthetic = True`` and every report that
includes one says so. An ``expert`` keeps a stable high skill; a ``trainee`` starts low
and improves with practice along an exponential curve towards a plateau near the
experts' (with a small loss at the delayed retention session and on a task it has
not practised); a slow learner levels off well short of it. Skill in [0, 1] sets
entry-angle spread, insertion speed, hesitations, tremor and how much the wrist turns
the needle rather than levering it.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from metrics.session.registry import REGISTRY_VERSION
from sessions.catalog import Catalog, now
from sessions.catalog.lookups import insert_rows
from sessions.catalog.models import MetricResult, Session
from sessions.catalog.results import study_sessions_with
from sessions.tasks import task_spec
from sim.devices.assisting import AssistingHandParameters, ScriptedHands
from sim.devices.scripted import SuturingPassParameters

PROFILES = ("expert", "trainee")


@dataclass(frozen=True)
class Profile:
    """A synthetic participant's skill over trials: an expert's stays at ``start_skill``; a
    trainee's rises from it towards ``plateau`` along an exponential curve (fast early gains, then a
    plateau: the shape of published simulator learning curves), with a small loss at the delayed
    retention session and on a task not practised."""

    kind: str
    start_skill: float
    learning_rate: float  # per practice trial
    plateau: float = 0.99  # where a trainee's curve levels off

    def skill(self, trial: int, phase: str = "practice") -> float:
        return self._curve(trial, phase, self.learning_rate)

    def placement_skill(self, trial: int, phase: str = "practice") -> float:
        """How accurately the hand places its bites: the same curve, learnt at ``PLACEMENT_LEARNING``
        of the rate (a modelling choice: aiming a curved needle at a mark improves more slowly than
        the motion)."""
        return self._curve(trial, phase, PLACEMENT_LEARNING * self.learning_rate)

    def transferred(self, trial: int) -> tuple[float, float]:
        """(motion, placement) skill on a task not practised, after ``trial`` practice trials of
        another: an expert's own; a trainee's less ``TRANSFER_LOSS`` (a new task's first attempt)."""
        loss = 0.0 if self.kind == "expert" else TRANSFER_LOSS
        return self.skill(trial) - loss, self.placement_skill(trial) - loss

    def _curve(self, trial: int, phase: str, rate: float) -> float:
        if self.kind == "expert":
            return self.start_skill
        skill = self.start_skill + (self.plateau - self.start_skill) * (1 - math.exp(-rate * (trial - 1)))
        return skill - (RETENTION_LOSS if phase == "retention" else 0.0)


PLACEMENT_LEARNING = 0.8
"""Placement accuracy's learning rate as a fraction of the motion's (synthetic trainees)."""
RETENTION_LOSS = 0.03
"""Skill a synthetic trainee loses between the last practice session and the delayed retention one: a
modelling choice, small next to what the practice gained (so a trainee who reached the experts keeps
it more often than not)."""
TRANSFER_LOSS = 0.25
"""Skill a synthetic trainee lacks on a task it has not practised (the final task after practice on
another): what practice on one task carries over to the next is partial."""
SLOW_LEARNER_PLATEAU = 0.6
"""Where a slow learner's curve levels off: well short of the experts (0.85-0.97); such a trainee
does not reach proficiency and is flagged for attention."""
SHALLOW_BITE_OFFSET = 1.1e-3
"""A bite taken this much too near the wound edge (0.4 mm from it on the interrupted stitch): the
needle's curve comes out through the cut edge, a partial-thickness bite."""


def profile_for(kind: str, seed: int, slow_learner: bool = False) -> Profile:
    """A synthetic participant's profile: an expert's steady skill 0.85-0.97; a trainee starting at
    0.05-0.3, learning at 0.6-1.0 per trial (within a few percent of its plateau after 4-7 trials)
    towards a plateau of 0.95-0.99, or, a ``slow_learner``, at 0.2-0.4 towards
    :data:`SLOW_LEARNER_PLATEAU`."""
    rng = np.random.default_rng(seed)
    if kind == "expert":
        return Profile("expert", float(rng.uniform(0.85, 0.97)), 0.0)
    if kind == "trainee":
        start = float(rng.uniform(0.05, 0.3))
        if slow_learner:
            return Profile("trainee", start, float(rng.uniform(0.2, 0.4)), SLOW_LEARNER_PLATEAU)
        return Profile("trainee", start, float(rng.uniform(0.6, 1.0)), float(rng.uniform(0.95, 0.99)))
    raise ValueError(f"synthetic profile must be one of {', '.join(PROFILES)}; got {kind!r}")


def pass_parameters(skill: float, seed: int, placement_skill: float | None = None) -> SuturingPassParameters:
    """A scripted pass for a given skill (0 = first-day trainee, 1 = expert); where the bite lands
    follows ``placement_skill`` (default: the same skill). A hand that places badly now and then
    (probability 0.3 x its placement clumsiness) takes its bite too near the edge, a partial-thickness
    bite out through the cut edge."""
    rng = np.random.default_rng(seed)
    clumsiness = 1.0 - min(max(skill, 0.0), 1.0)
    aim = clumsiness if placement_skill is None else 1.0 - min(max(placement_skill, 0.0), 1.0)
    angle = float(abs(rng.normal(2.0 + 26.0 * clumsiness, 1.5 + 4.0 * clumsiness)))
    speed = float(0.003 + 0.007 * clumsiness + rng.normal(0, 0.0003))
    hesitations = int(rng.binomial(3, clumsiness))
    # where the bite lands, off the mark: across the bite an expert's hand is within ~0.1 mm, a
    # first-day trainee's ~0.8 mm off (sd 1.2 mm); along it (the bite's size) 0.4 of that, which
    # keeps every bite clear of the wound edge. Drawn after the other parameters, so a seed's other
    # parameters are what they always were.
    spread = 1e-4 + 1.1e-3 * aim
    along = float(np.clip(rng.normal(0.0, 0.4 * spread), -0.5e-3, 0.5e-3))
    across = float(np.clip(rng.normal(0.0, spread), -1.2e-3, 1.2e-3))
    if rng.random() < 0.3 * aim:  # drawn last: a seed's other parameters are what they were
        along = SHALLOW_BITE_OFFSET
    return SuturingPassParameters(
        entry_angle_deg=angle,
        insertion_speed=speed,
        wrist_rotation=float(1.0 - 0.5 * clumsiness),
        hesitations=hesitations,
        hesitation_time=0.3,
        tremor_amplitude=float(2e-5 + 2.5e-4 * clumsiness),
        approach_time=float(0.6 + 0.6 * clumsiness),
        regrab_time=float(0.4 + 0.6 * clumsiness),
        # slow and steady into the wall, brisk through it once regrasped: an expert pulls through at
        # ~7 mm/s, a first-day trainee at ~5 (at its insertion speed an expert's stitch was the slowest)
        pull_speed=float(0.007 - 0.002 * clumsiness),
        entry_offset=along,
        lateral_offset=across,
        seed=seed,
    )


def assisting_parameters(skill: float, seed: int) -> AssistingHandParameters:
    """The scripted subordinate hand for a given skill (0 = first-day trainee, 1 = expert): an expert
    takes the edge by a third of the needle's approach and steadies it, lifted 0.12 mm; a first-day
    trainee leaves it alone in about half the sessions, and when it does take it, takes it up to a
    second late and lifts it up to about 1.4 mm (an edge lifted about 1.9 mm tears out of the jaws
    and stops the needle piercing; no synthetic hand goes that far, so every scripted bite still
    pierces); it shakes, holding or not. The needle hand aims at the bite as planned at rest, so a lifted
    edge meets it tilted (about 2 deg per 0.1 mm on the interrupted stitch, measured against the wall
    where it is: an edge lifted too far costs the entry angle). Drawn from its own stream of
    ``seed``: the needle hand's draws are unchanged."""
    rng = np.random.default_rng(seed + 104729)
    clumsiness = 1.0 - min(max(skill, 0.0), 1.0)
    grasps = bool(rng.random() >= 0.55 * clumsiness)
    delay = float(clumsiness * rng.uniform(0.2, 1.1))
    eversion = float(EXPERT_EVERSION_M + 0.9e-3 * clumsiness * rng.uniform(0.5, 1.5))
    return AssistingHandParameters(
        grasps=grasps,
        grasp_delay=delay,
        eversion=eversion,
        tremor_amplitude=float(2e-5 + 3e-4 * clumsiness),
        seed=seed,
    )


EXPERT_EVERSION_M = 0.12e-3
"""How far a scripted expert lifts a wound's edge before an ordinary bite (m)."""


def for_everted_bite(assisting: AssistingHandParameters, lift: float) -> AssistingHandParameters:
    """The same subordinate hand on a bite that needs the edge lifted ``lift`` (m): it lifts that far
    plus whatever it over-lifts an ordinary bite's edge (a trainee's excess stays; a hand that leaves
    the edge alone still does)."""
    return dataclasses.replace(assisting, eversion=assisting.eversion - EXPERT_EVERSION_M + lift)


def aimed_bites(spec) -> list[tuple]:
    """The bites a scripted needle hand aims at, (entry, normal, bite_direction) each: the task's own,
    or, on a task whose bite needs the edge everted (``spec.eversion``), with the wrist at its stop:
    the tip as far back as the approach lets it turn (``short_deg`` past square to the resting wall,
    towards the bite) on the entry mark, which the wall everted by the task's lift (``turn_deg``)
    meets nearly square and the resting wall does not. (Aimed square to the everted wall itself, its
    circle turned 8.9 deg about the entry and 170 deg of pull, the needle's far side then swept the
    patch's side in four of five expert sessions: "needle enters a second wall".)"""
    if spec.eversion is None:
        return spec.bites()
    turn = math.radians(spec.eversion.short_deg)
    aimed = []
    for entry, normal, bite_direction in spec.bites():
        n = np.asarray(normal, dtype=np.float64) / np.linalg.norm(normal)
        s = np.asarray(bite_direction, dtype=np.float64)
        s = (s - (s @ n) * n) / np.linalg.norm(s - (s @ n) * n)
        turned = (math.cos(turn) * n - math.sin(turn) * s, math.cos(turn) * s + math.sin(turn) * n)
        aimed.append((entry, *turned))
    return aimed


def scripted_hands(skill: float, seed: int, placement_skill: float | None = None) -> ScriptedHands:
    """Both hands of a scripted session of a given skill: :func:`pass_parameters` and
    :func:`assisting_parameters`."""
    return ScriptedHands(pass_parameters(skill, seed, placement_skill), assisting_parameters(skill, seed))


def bite_parameters(parameters: SuturingPassParameters, count: int) -> list[SuturingPassParameters]:
    """The parameters of each of ``count`` bites of one session: the first as given; each later one
    the same hand, its tremor phases re-drawn and its miss of the mark varying around the first
    bite's (so a steady hand places a row evenly and an unsteady one does not)."""
    rng = np.random.default_rng(parameters.seed + 7919)
    result = [parameters]
    for k in range(1, count):
        along, across = rng.normal(1.0, 1.0, size=2)
        result.append(
            dataclasses.replace(
                parameters,
                seed=parameters.seed + k,
                entry_offset=float(np.clip(parameters.entry_offset * along, -0.5e-3, 0.5e-3)),
                lateral_offset=float(np.clip(parameters.lateral_offset * across, -1.2e-3, 1.2e-3)),
            )
        )
    return result


def in_restricted_access(parameters: SuturingPassParameters, tilt_deg: float) -> SuturingPassParameters:
    """The same hand where it can only come in ``tilt_deg`` off the wall's normal: the further turn
    of the wrist magnifies what it already gets wrong, by 1 + sin(tilt) (1.71 at 45 deg): its entry
    angle error, and the share of the needle's advance it levers instead of turning. A steady expert
    entering 2 deg off enters 3.4 deg off; a first-day trainee's 20 deg becomes 34 deg. A modelling
    choice for synthetic hands (the source paper trains the dominant hand by varying access), not a
    measured law."""
    factor = 1.0 + math.sin(math.radians(tilt_deg))
    return dataclasses.replace(
        parameters,
        entry_angle_deg=parameters.entry_angle_deg * factor,
        wrist_rotation=max(0.0, 1.0 - (1.0 - parameters.wrist_rotation) * factor),
    )


# (metric, expert typical value, trainee first-day value, relative spread) for metrics-only studies
SYNTHETIC_METRICS = (
    ("task_time", 6.0, 14.0, 0.15),
    ("path_length", 0.06, 0.14, 0.15),
    ("movement_count", 4.0, 11.0, 0.25),
    ("economy_of_motion", 0.8, 0.45, 0.1),
    ("spectral_arc_length", -2.0, -4.5, 0.1),
    ("idle_time", 0.5, 2.5, 0.3),
    ("tip_speed_before_pierce", 0.0035, 0.009, 0.15),
    ("tip_speed_after_pierce", 0.003, 0.008, 0.15),
    ("entry_angle_error_deg", 3.0, 22.0, 0.3),
    ("peak_force", 0.25, 0.6, 0.2),
    ("mean_force", 0.08, 0.2, 0.2),
    ("peak_stretch", 1.08, 1.3, 0.05),
)


def seed_metrics_study(
    catalog: Catalog,
    study_name: str,
    experts: int,
    trainees: int,
    sessions_each: int,
    seed: int = 0,
    task: str = "wall-stitch",
) -> int:
    """A synthetic study of metrics only (no streams): experts steady, trainees improving along an
    exponential curve. Rows go in with bulk inserts, so 10,000 sessions take seconds. Returns the study id."""
    rng = np.random.default_rng(seed)
    spec = task_spec(task)
    started = now()
    with catalog.session() as orm:
        study = catalog.study(orm, study_name, create=True, description="Synthetic metrics-only study")
        task_row = catalog.task(orm, spec.name, spec.scenario, spec.parameters.as_dict())
        people = [("expert", k) for k in range(1, experts + 1)]
        people += [("trainee", k) for k in range(1, trainees + 1)]
        session_rows, progress = [], []
        for kind, k in people:
            code = f"{kind[0].upper()}{k:04d}"
            participant = catalog.add_participant(orm, study, code, kind, kind, synthetic=True)
            rate = rng.uniform(0.2, 0.6)
            for trial in range(1, sessions_each + 1):
                session_rows.append(
                    {
                        "uid": f"Z{seed}-{participant.id:05d}-{trial:04d}",
                        "participant_id": participant.id,
                        "task_id": task_row.id,
                        "device": "synthetic",
                        "clock": "simulated",
                        "trial": trial,
                        "phase": "practice",
                        "status": "complete",
                        "started_at": started,
                        "ended_at": started,
                        "directory": "",
                        "error": "",
                    }
                )
                progress.append(1.0 if kind == "expert" else 1.0 - math.exp(-rate * (trial - 1)))
        insert_rows(orm, Session, session_rows)
        ids = {uid: sid for sid, uid in study_sessions_with(orm, study.id, ("complete",))}
        metric_rows = [
            {
                "session_id": ids[row["uid"]],
                "metric": name,
                "value": float((novice + (expert - novice) * share) * (1.0 + spread * rng.standard_normal())),
                "registry_version": REGISTRY_VERSION,
            }
            for row, share in zip(session_rows, progress, strict=True)
            for name, expert, novice, spread in SYNTHETIC_METRICS
        ]
        insert_rows(orm, MetricResult, metric_rows)
        return study.id
