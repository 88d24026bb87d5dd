"""A task: its scenario (mesh, materials, held nodes), its bites and what it scores against."""

from __future__ import annotations

from dataclasses import dataclass

from sessions.tasks.parameters import TaskParameters


@dataclass(frozen=True)
class EvertedBite:
    """A bite that cannot be made square without everting the wound's edge: the approach stops the
    wrist ``short_deg`` short of square to the resting wall, tipped towards the bite
    (:class:`sim.needle.reach.WristStop`); the forceps lifting the rim ``lift_m`` turn the wall at the
    entry ``turn_deg`` away from the wound (measured on the task's mesh by
    :func:`sim.forceps.eversion.wall_turn`; a test holds the task to it), past the stop, so an entry
    square to the everted wall is within the wrist's reach."""

    short_deg: float
    lift_m: float
    turn_deg: float


@dataclass(frozen=True)
class TaskSpec:
    name: str
    scenario: str
    description: str
    entry: tuple[float, float, float]
    normal: tuple[float, float, float]
    bite_direction: tuple[float, float, float]
    parameters: TaskParameters
    """What the task's kind builds it from (:mod:`sessions.tasks.parameters`); stored as
    ``parameters.as_dict()``."""
    placement: dict | None = None
    """The wound edge and target marks placement metrics score against (SI units; see
    :class:`metrics.signals.placement.PlacementTargets`); recorded in each session's header."""
    more_bites: tuple = ()
    """Further bites after the first, in the order they are made: (entry, normal, bite_direction)."""
    access: dict | None = None
    """Restricted access: ``approach`` (unit vector from the entry point: the only direction the
    hand can come from) and ``tilt_deg`` (its angle from the wall's normal); None: open access."""
    time_budget_s: float = 60.0
    """The time a course allows for the task (s): chosen at about ten times a scripted expert's."""
    eversion: EvertedBite | None = None
    """A bite that needs the subordinate hand to evert the edge first (None: the wrist reaches square)."""

    @property
    def stitch_count(self) -> int:
        """The stitches the task asks for (one per target entry mark; one without marks)."""
        return len(self.placement["entry_targets"]) if self.placement else 1

    @property
    def primary_metrics(self) -> tuple[str, ...]:
        """The metrics a study of this task analyses unless it declares others, chosen before any data:
        the source paper's proposed needle velocity near the insertion point (before and after
        piercing), its perpendicular-entry criterion, the hand's smoothness (the wrist should turn the
        needle smoothly), and, where the task marks targets, where the bite went against its mark. A
        short declared list keeps the multiple-comparison correction from diluting what matters."""
        needle = ("tip_speed_before_pierce", "tip_speed_after_pierce", "entry_angle_error_deg")
        hand = ("spectral_arc_length",)
        placement = ("entry_to_target",) if self.placement else ()
        return needle + hand + placement

    def bites(self) -> list[tuple]:
        """Every bite of the task, in order: (entry, normal, bite_direction) each (m, unit vectors)."""
        return [(self.entry, self.normal, self.bite_direction), *self.more_bites]
