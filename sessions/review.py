"""One session against the experts: the study's expert band per metric, read by the metric's direction.

The dashboard's session page and ``vascsim sessions show`` both call
:func:`session_against_experts`, so a value reads the same wherever it is shown.
"""

from __future__ import annotations

import math

import pandas as pd
from sqlalchemy import select

from metrics.proficiency import band_position
from metrics.registry import REGISTRY, REGISTRY_VERSION
from metrics.units import display_unit, in_display_units
from sessions.catalog import Catalog
from sessions.models import MetricResult, Participant, Session, StitchResult
from sessions.status import SCORABLE

EXPERT_GROUP = "expert"


def expert_band(catalog: Catalog, study_id: int, task_id: int) -> dict[str, dict]:
    """Per metric, the quartiles of the study's expert sessions on the same task (current registry)."""
    with catalog.session() as orm:
        rows = orm.execute(
            select(MetricResult.metric, MetricResult.value)
            .join(Session, MetricResult.session_id == Session.id)
            .join(Participant, Session.participant_id == Participant.id)
            .where(
                Participant.study_id == study_id,
                Participant.group_label == EXPERT_GROUP,
                Session.task_id == task_id,
                Session.status.in_(SCORABLE),
                MetricResult.registry_version == REGISTRY_VERSION,
                MetricResult.value.is_not(None),
            )
        ).all()
    if not rows:
        return {}
    frame = pd.DataFrame(rows, columns=["metric", "value"])
    quartiles = frame.groupby("metric")["value"].quantile([0.25, 0.5, 0.75]).unstack()
    return {
        name: {"expert_q1": float(q[0.25]), "expert_median": float(q[0.5]), "expert_q3": float(q[0.75])}
        for name, q in quartiles.iterrows()
    }


def against_band(values: dict[str, float | None], band: dict[str, dict]) -> list[dict]:
    """One row per metric: value, unit, direction, the expert quartiles and ``versus_experts`` (SI),
    and the same in display units (``display_unit``, ``display``: value and quartiles).

    ``versus_experts`` is "better", "within" or "worse" than the experts' interquartile band by
    the metric's registry direction (a shorter task time than every expert is better), or None
    where the value or the band is missing.
    """
    rows = []
    empty = {"expert_q1": None, "expert_median": None, "expert_q3": None}
    for name, value in values.items():
        known = name in REGISTRY
        better = REGISTRY[name].better if known else ""
        quartiles = band.get(name, empty)
        finite = value is not None and math.isfinite(value)
        position = None
        if finite and known and quartiles["expert_q1"] is not None:
            position = band_position(value, quartiles["expert_q1"], quartiles["expert_q3"], better)
        unit = REGISTRY[name].unit if known else ""
        rows.append(
            {
                "metric": name,
                "unit": unit,
                "better": better,
                "value": value if finite else None,
                **quartiles,
                "versus_experts": position,
                # the same numbers in the units a surgeon reads (metrics.units), for every front-end
                "display_unit": display_unit(unit),
                "display": {
                    key: in_display_units(v, unit)
                    for key, v in (("value", value if finite else None), *quartiles.items())
                },
            }
        )
    return rows


def session_against_experts(catalog: Catalog, uid: str) -> list[dict]:
    """A session's current-registry metrics against its study's expert band on the same task."""
    with catalog.session() as orm:
        row = catalog.recorded_session(orm, uid)
        values = {
            m.metric: m.value
            for m in sorted(row.metrics, key=lambda m: m.id)
            if m.registry_version == REGISTRY_VERSION
        }
        study_id, task_id = row.participant.study_id, row.task_id
    return against_band(values, expert_band(catalog, study_id, task_id))


def session_stitches(catalog: Catalog, uid: str) -> list[dict]:
    """A session's stitches (current registry), one dict each: ``stitch`` and each stored quantity
    (:data:`metrics.placement.STITCH_QUANTITIES`, SI units; None where it does not apply)."""
    with catalog.session() as orm:
        row = catalog.recorded_session(orm, uid)
        results = orm.execute(
            select(StitchResult.stitch, StitchResult.quantity, StitchResult.value)
            .where(StitchResult.session_id == row.id, StitchResult.registry_version == REGISTRY_VERSION)
            .order_by(StitchResult.stitch)
        ).all()
    stitches: dict[int, dict] = {}
    for stitch, quantity, value in results:
        stitches.setdefault(stitch, {"stitch": stitch})[quantity] = value
    return list(stitches.values())
