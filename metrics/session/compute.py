"""Per-session metrics: every registered metric for each session, one row per session."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from metrics.errors import MetricsError
from metrics.session import force, insertion, motion, placement, subordinate_hand, tissue
from metrics.session.context import SessionContext
from metrics.session.registry import REGISTRY, REGISTRY_VERSION
from metrics.signals.tissue import with_tissue_fields
from metrics.streams import SessionStreams, from_recorded
from recorder import open_session

METRIC_GROUPS = (motion, insertion, force, tissue, placement, subordinate_hand)
"""The modules whose ``@metric`` functions fill :data:`REGISTRY` as they are imported: a new group
is a module in ``metrics/session/`` and its line here."""

ID_COLUMNS = ("session_id", "participant_id", "label")
ATTRIBUTE_COLUMNS = ("trial", "grs", "phase", "synthetic", "task")
"""Session attributes copied next to the metrics when any session has them."""


def as_streams(item: Any) -> SessionStreams:
    """A SessionStreams from a SessionStreams, a recorder Session, a session directory, or a trial object."""
    if isinstance(item, SessionStreams):
        return item
    if hasattr(item, "to_streams"):
        return item.to_streams()
    if isinstance(item, str | Path):
        return from_recorded(open_session(item))
    if hasattr(item, "samples") and hasattr(item, "header"):
        return from_recorded(item)
    raise MetricsError(
        f"cannot compute metrics of a {type(item).__name__}; give SessionStreams, a recorded session "
        "(or its directory) or an imported trial"
    )


def metrics_of(streams: SessionStreams, names: Sequence[str] | None = None) -> dict[str, float]:
    """Every (or the named) registered metric of one session; NaN where a needed stream is missing."""
    context = SessionContext(streams)
    values = {}
    for metric in REGISTRY.select(list(names) if names is not None else None):
        if not all(streams.has(s) for s in metric.streams):
            values[metric.name] = math.nan
            continue
        value = metric.compute(context)
        values[metric.name] = float(value) if value is not None else math.nan
    return values


def session_row(streams: SessionStreams, names: Sequence[str] | None = None) -> dict[str, Any]:
    row: dict[str, Any] = {
        "session_id": streams.session_id,
        "participant_id": streams.participant_id,
        "label": streams.label,
    }
    for key in ATTRIBUTE_COLUMNS:
        if key in streams.attributes:
            row[key] = streams.attributes[key]
    row.update(metrics_of(streams, names))
    return row


def compute_session_metrics(
    sessions_or_trials: Iterable[Any],
    metrics: Sequence[str] | None = None,
    progress: Callable[[int], None] | None = None,
    tissue: Callable[[SessionStreams], Any] | None = None,
) -> pd.DataFrame:
    """One row per session: ``session_id``, ``participant_id``, ``label``, attributes, one column per metric.

    sessions_or_trials: SessionStreams, recorder sessions or their directories,
    imported trials (e.g. :func:`metrics.datasets.jigsaws.load`), in any mix.
    metrics: names to compute (default: the whole registry). progress: called with
    1 after each session. tissue: for simulator sessions, a function giving the tissue
    model a session ran on (or None), from which :func:`metrics.signals.tissue.with_tissue_fields`
    derives the tissue streams. ``frame.attrs["registry_version"]`` records the definitions used.
    """
    rows = []
    for item in sessions_or_trials:
        streams = as_streams(item)
        model = tissue(streams) if tissue is not None else None
        if model is not None:
            streams = with_tissue_fields(streams, model)
        rows.append(session_row(streams, metrics))
        if progress is not None:
            progress(1)
    names = [m.name for m in REGISTRY.select(list(metrics) if metrics is not None else None)]
    frame = pd.DataFrame(rows)
    if frame.empty:
        frame = pd.DataFrame(columns=[*ID_COLUMNS, *names])
    present = [c for c in ATTRIBUTE_COLUMNS if c in frame.columns]
    frame = frame[[*ID_COLUMNS, *present, *names]]
    frame[names] = frame[names].astype(np.float64)
    frame.attrs["registry_version"] = REGISTRY_VERSION
    return frame
