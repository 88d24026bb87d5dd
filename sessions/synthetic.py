"""Synthetic participants: scripted suturing passes whose skill parameters differ by profile.

Every synthetic participant is stored with ``synthetic = True`` and every report that
includes one says so. An ``expert`` keeps a stable high skill; a ``trainee`` starts low
and improves with practice along an exponential curve (with a small loss at the
delayed retention session). Skill in [0, 1] sets entry-angle spread, insertion speed,
hesitations, tremor and how much the wrist turns the needle rather than levering it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sim.devices.scripted import SuturingPassParameters

PROFILES = ("expert", "trainee")


@dataclass(frozen=True)
class Profile:
    kind: str
    start_skill: float
    learning_rate: float  # per practice trial

    def skill(self, trial: int, phase: str = "practice") -> float:
        if self.kind == "expert":
            return self.start_skill
        skill = self.start_skill + (0.99 - self.start_skill) * (
            1 - math.exp(-self.learning_rate * (trial - 1))
        )
        return skill - (0.08 if phase == "retention" else 0.0)


def profile_for(kind: str, seed: int) -> Profile:
    rng = np.random.default_rng(seed)
    if kind == "expert":
        return Profile("expert", float(rng.uniform(0.85, 0.97)), 0.0)
    if kind == "trainee":
        return Profile("trainee", float(rng.uniform(0.05, 0.3)), float(rng.uniform(0.5, 0.9)))
    raise ValueError(f"synthetic profile must be one of {', '.join(PROFILES)}; got {kind!r}")


def pass_parameters(skill: float, seed: int) -> SuturingPassParameters:
    """A scripted pass for a given skill (0 = first-day trainee, 1 = expert)."""
    rng = np.random.default_rng(seed)
    clumsiness = 1.0 - min(max(skill, 0.0), 1.0)
    return SuturingPassParameters(
        entry_angle_deg=float(abs(rng.normal(2.0 + 26.0 * clumsiness, 1.5 + 4.0 * clumsiness))),
        insertion_speed=float(0.003 + 0.007 * clumsiness + rng.normal(0, 0.0003)),
        wrist_rotation=float(1.0 - 0.5 * clumsiness),
        hesitations=int(rng.binomial(3, clumsiness)),
        hesitation_time=0.3,
        tremor_amplitude=float(2e-5 + 2.5e-4 * clumsiness),
        approach_time=float(0.6 + 0.6 * clumsiness),
        regrab_time=float(0.4 + 0.6 * clumsiness),
        seed=seed,
    )
