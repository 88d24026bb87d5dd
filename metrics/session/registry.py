"""The one registry of per-session metrics: name, unit, definition, streams, direction, reference.

Every metric is a function of a :class:`metrics.session.context.SessionContext`; registering
it here is what makes it part of ``compute_session_metrics``, the reports and the
catalog. ``REGISTRY_VERSION`` is stored with every metric result: bump it when a
definition or a threshold changes, so old and new numbers are never mixed.
"""

from __future__ import annotations

import importlib
import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING

from metrics.errors import MetricsError

if TYPE_CHECKING:
    from metrics.session.context import SessionContext

REGISTRY_VERSION = "10"
"""8: ``stretch`` (peak_stretch, time_above_strain_limit) is the largest edge stretch around the contact
in the field the display draws, no longer 1 + |d|/h (issue 43). 9: the subordinate hand's metrics from
its recorded forceps (edge_held_at_insertion, peak_grasp_force, forceps_tears added), and not measured
(NaN) for a session recorded one-handed, where they had read zeros (issue 46). 10: bimanual_dexterity
added (issue 46)."""

LOWER, HIGHER = "lower", "higher"
KINDS = ("safety", "quality", "efficiency")
"""What a metric is about, in the order feedback ranks it: what harms the patient (never events,
partial-thickness bites and extra punctures, excessive force, the load on the tissue, an edge the
forceps tear or crush), what makes the anastomosis (where the stitch went), then speed and economy."""


@dataclass(frozen=True)
class Metric:
    """One per-session metric.

    better: ``"lower"`` or ``"higher"``, which values indicate more skill.
    advice: required when registering (:func:`metric`): a new metric brings its own feedback.
    streams: the session streams it needs (``SessionStreams`` attribute names, or
    ``"events"``); without them the value is NaN.
    bounds: the values the metric can take (a time or an angle error is never negative,
    SPARC never positive); learning curves are fitted inside them.
    kind: one of :data:`KINDS` (the feedback's ranking: :mod:`metrics.reading.feedback`).
    """

    name: str
    unit: str
    definition: str
    streams: tuple[str, ...]
    better: str
    reference: str
    group: str
    kind: str
    compute: Callable[[SessionContext], float]
    bounds: tuple[float, float] = (-math.inf, math.inf)
    advice: str = ""
    """What a better attempt does, in a sentence a supervisor would say (the feedback a trainee reads
    when the metric is worse than the experts': :mod:`metrics.reading.feedback`)."""

    def __post_init__(self) -> None:
        if self.better not in (LOWER, HIGHER):
            raise MetricsError(
                f"metric {self.name!r}: better must be 'lower' or 'higher'; got {self.better!r}"
            )
        if self.kind not in KINDS:
            raise MetricsError(
                f"metric {self.name!r}: kind must be one of {', '.join(KINDS)}; got {self.kind!r}"
            )

    @property
    def sign(self) -> int:
        """+1 when higher values are better, -1 when lower values are better."""
        return 1 if self.better == HIGHER else -1


class Registry:
    """Ordered collection of metrics, looked up by name. Reading it first imports the metric groups
    (:data:`metrics.session.compute.METRIC_GROUPS`, whose ``@metric`` functions fill it), so no
    reader depends on which modules happened to be imported before."""

    def __init__(self) -> None:
        self._metrics: dict[str, Metric] = {}
        self._complete = False

    def add(self, metric: Metric) -> Metric:
        if metric.name in self._metrics:
            raise MetricsError(f"metric {metric.name!r} is registered twice")
        self._metrics[metric.name] = metric
        return metric

    @property
    def _every(self) -> dict[str, Metric]:
        if not self._complete:
            self._complete = True  # before the import: a group reading the registry as it loads
            try:
                importlib.import_module("metrics.session.compute")
            except BaseException:
                self._complete = False  # a failed import is raised again by the next read
                raise
        return self._metrics

    def __getitem__(self, name: str) -> Metric:
        try:
            return self._every[name]
        except KeyError:
            known = ", ".join(self._metrics)
            raise MetricsError(f"unknown metric {name!r}; known metrics: {known}") from None

    def __contains__(self, name: object) -> bool:
        return name in self._every

    def __iter__(self) -> Iterator[Metric]:
        return iter(self._every.values())

    def __len__(self) -> int:
        return len(self._every)

    def names(self) -> list[str]:
        return list(self._every)

    def select(self, names: list[str] | None) -> list[Metric]:
        return list(self) if names is None else [self[n] for n in names]

    def describe(self):
        """The registry as a DataFrame (name, unit, better, range, group, kind, streams, definition,
        advice, reference)."""
        import pandas as pd

        return pd.DataFrame(
            [
                {
                    "name": m.name,
                    "unit": m.unit,
                    "better": m.better,
                    "range": f"[{m.bounds[0]:g}, {m.bounds[1]:g}]",
                    "group": m.group,
                    "kind": m.kind,
                    "streams": ", ".join(m.streams),
                    "definition": m.definition,
                    "advice": m.advice,
                    "reference": m.reference,
                }
                for m in self
            ]
        )


REGISTRY = Registry()

TITLES = {
    "entry_angle_error_deg": "entry angle error",
    "tip_speed_before_pierce": "tip speed before piercing",
    "tip_speed_after_pierce": "tip speed after piercing",
    "spectral_arc_length": "smoothness (SPARC)",
    "log_dimensionless_jerk": "smoothness (log dimensionless jerk)",
    "entry_to_target": "entry distance from its mark",
    "exit_to_target": "exit distance from its mark",
    "bite_error_entry": "bite error at entry",
    "bite_error_exit": "bite error at exit",
    "contact_to_pierce_time": "time from contact to piercing",
    "force_at_insertion": "force at insertion",
    "peak_force_rate": "peak force rate",
    "rms_force": "RMS force",
    "high_stress_area": "area under high stress",
    "time_above_strain_limit": "time above the strain limit",
    "full_thickness_fraction": "full-thickness bites",
    "needle_track_offset": "needle track offset",
}
"""Metric names as a surgeon reads them where the generated one ("task time") would not do."""


def display_name(name: str) -> str:
    """A metric's name for a person ("entry angle error", "task time"); the stored name stays the key."""
    return TITLES.get(name, name.replace("_", " "))


def metric(
    name: str,
    *,
    unit: str,
    definition: str,
    advice: str,
    streams: tuple[str, ...] = (),
    better: str,
    reference: str,
    group: str,
    kind: str,
    bounds: tuple[float, float] = (0.0, math.inf),
) -> Callable[[Callable[[SessionContext], float]], Callable[[SessionContext], float]]:
    """Decorator registering a metric function in :data:`REGISTRY` (by default a non-negative quantity);
    ``advice``: what a better attempt does, one sentence ending in a full stop; ``kind``: safety,
    quality or efficiency (:data:`KINDS`)."""
    if not advice.endswith(".") or len(advice) >= 90:
        raise MetricsError(f"metric {name!r}: advice must be one sentence under 90 characters, ending in '.'")

    def register(function: Callable[[SessionContext], float]) -> Callable[[SessionContext], float]:
        REGISTRY.add(
            Metric(name, unit, definition, streams, better, reference, group, kind, function, bounds, advice)
        )
        return function

    return register
