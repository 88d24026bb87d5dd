"""One session against the experts: the study's expert band per metric, read by the metric's direction.

The dashboard's session page and ``vascsim sessions show`` both call
:func:`session_against_experts`, so a value reads the same wherever it is shown; the reading itself
is :func:`metrics.band.against_band` (re-exported here).
"""

from __future__ import annotations

import pandas as pd
from sqlalchemy import select

from metrics.band import against_band, expert_quartiles
from metrics.registry import REGISTRY_VERSION
from sessions.catalog import Catalog
from sessions.models import MetricResult, Participant, Session, StitchResult
from sessions.status import SCORABLE

EXPERT_GROUP = "expert"

__all__ = ["EXPERT_GROUP", "against_band", "expert_band", "session_against_experts", "session_stitches"]


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
    return expert_quartiles(pd.DataFrame(rows, columns=["metric", "value"]))


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
