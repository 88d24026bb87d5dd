"""Rating instruments raters score sessions with: their items, scale and anchors.

- ``GRS``: the global rating score of JIGSAWS (Gao et al. 2014), six items scored 1-5, a
  modified OSATS; JIGSAWS ships it per trial (total 6-30).
- ``OSATS``: the global rating scale of the Objective Structured Assessment of Technical
  Skill (Martin et al. 1997, Br J Surg 84:273), seven items scored 1-5 (total 7-35).

Anchors (1, 3, 5) are short paraphrases for the rating form; a course should train its raters
on the instrument's published descriptors.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

from metrics.errors import MetricsError

TOTAL = "total"


@dataclass(frozen=True)
class Item:
    name: str
    label: str
    anchors: tuple[str, str, str]  # what a 1, a 3 and a 5 look like


@dataclass(frozen=True)
class Instrument:
    name: str
    title: str
    reference: str
    items: tuple[Item, ...]
    low: int = 1
    high: int = 5

    @property
    def item_names(self) -> tuple[str, ...]:
        return tuple(item.name for item in self.items)

    @property
    def total_range(self) -> tuple[int, int]:
        return self.low * len(self.items), self.high * len(self.items)

    def checked(self, scores: Mapping[str, object]) -> dict[str, int]:
        """Every item scored once, each a whole number on the scale; nothing else. Raises
        :class:`MetricsError` naming the first problem."""
        unknown = sorted(set(scores) - set(self.item_names) - {TOTAL})
        if unknown:
            raise MetricsError(
                f"{self.name} has no item {unknown[0]!r}; its items: {', '.join(self.item_names)}"
            )
        missing = [name for name in self.item_names if name not in scores]
        if missing:
            raise MetricsError(
                f"{self.name} rating is missing item(s) {', '.join(missing)}: score every item"
            )
        result = {}
        for name in self.item_names:
            result[name] = self._score(name, scores[name])
        if TOTAL in scores and self._number(TOTAL, scores[TOTAL]) != sum(result.values()):
            raise MetricsError(
                f"{self.name} total {scores[TOTAL]} is not the sum of its items ({sum(result.values())})"
            )
        return result

    def _number(self, name: str, value: object) -> float:
        try:
            number = float(value)  # type: ignore[arg-type]
        except (TypeError, ValueError):
            raise MetricsError(f"{self.name} item {name!r}: {value!r} is not a number") from None
        if not math.isfinite(number):
            raise MetricsError(f"{self.name} item {name!r}: {value!r} is not a finite number")
        return number

    def _score(self, name: str, value: object) -> int:
        number = self._number(name, value)
        if number != int(number) or not self.low <= number <= self.high:
            raise MetricsError(
                f"{self.name} item {name!r}: {value!r} is not a whole score from {self.low} to {self.high}"
            )
        return int(number)


GRS = Instrument(
    "GRS",
    "JIGSAWS global rating score (modified OSATS)",
    "Gao et al. 2014, JIGSAWS (MICCAI M2CAI workshop); Martin et al. 1997, Br J Surg 84:273",
    (
        Item(
            "respect_for_tissue",
            "Respect for tissue",
            (
                "frequent unnecessary force, tissue damaged",
                "careful, occasional damage",
                "consistently gentle",
            ),
        ),
        Item(
            "suture_needle_handling",
            "Suture and needle handling",
            (
                "awkward, frequent re-grasps",
                "competent, some awkward moves",
                "fluid, needle follows its curve",
            ),
        ),
        Item(
            "time_and_motion",
            "Time and motion",
            ("many unnecessary moves", "efficient, some unnecessary moves", "economy of movement"),
        ),
        Item(
            "flow_of_operation",
            "Flow of operation",
            ("frequent stops, unsure of the next move", "some forward planning", "planned, effortless flow"),
        ),
        Item(
            "overall_performance",
            "Overall performance",
            ("very poor", "competent", "clearly superior"),
        ),
        Item(
            "quality_of_final_product",
            "Quality of final product",
            ("bites uneven, off the marks", "acceptable", "even, on the marks"),
        ),
    ),
)

OSATS = Instrument(
    "OSATS",
    "OSATS global rating scale",
    "Martin et al. 1997, Br J Surg 84:273; Reznick et al. 1997, Am J Surg 173:226",
    (
        Item(
            "respect_for_tissue",
            "Respect for tissue",
            ("unnecessary force, damage", "careful, occasional damage", "consistently gentle"),
        ),
        Item(
            "time_and_motion",
            "Time and motion",
            ("many unnecessary moves", "efficient, some unnecessary moves", "clear economy of movement"),
        ),
        Item(
            "instrument_handling",
            "Instrument handling",
            ("tentative or awkward", "competent, occasionally stiff", "fluid"),
        ),
        Item(
            "knowledge_of_instruments",
            "Knowledge of instruments",
            (
                "wrong instruments, or asks for them by the wrong name",
                "knows most instruments",
                "familiar with all",
            ),
        ),
        Item(
            "use_of_assistants",
            "Use of assistants",
            (
                "places assistants poorly or not at all",
                "good use most of the time",
                "strategic use throughout",
            ),
        ),
        Item(
            "flow_of_operation",
            "Flow of operation and forward planning",
            ("frequent stops, unsure of the next move", "some forward planning", "planned, effortless flow"),
        ),
        Item(
            "knowledge_of_procedure",
            "Knowledge of specific procedure",
            ("deficient, needed instruction", "knew the important steps", "familiar with every step"),
        ),
    ),
)

INSTRUMENTS: dict[str, Instrument] = {i.name: i for i in (GRS, OSATS)}


def instrument(name: str) -> Instrument:
    """The instrument called ``name`` (case-insensitive): ``GRS`` or ``OSATS``."""
    key = name.upper()
    if key not in INSTRUMENTS:
        raise MetricsError(f"unknown rating instrument {name!r}; choose one of {', '.join(INSTRUMENTS)}")
    return INSTRUMENTS[key]
