"""Study analyses for the dashboard, computed once per catalog state and kept in memory.

A study's analysis (construct validity, benchmarks, proficiency, learning curves) is
the same computation as `vascsim report`: :func:`sessions.scoring.analysis.analyse_catalog_study`
from the study's declared analysis. It depends only on the study's scored
sessions and its declaration, so it is cached under a fingerprint of the catalog's sessions,
metric results, participants and declarations: any new score, session, relabelling or
declared version recomputes it.
"""

from __future__ import annotations

import math
import threading
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pandas as pd

from metrics.study.analysis import StudyAnalysis, oriented
from sessions.catalog.store import CatalogStore
from sessions.scoring.analysis import analyse_catalog_study

CACHED_STUDIES = 16


@dataclass(frozen=True)
class CachedAnalysis:
    analysis: StudyAnalysis
    uid_of: dict[str, int]  # session uid -> row of analysis.sessions


class AnalysisCache:
    """Per-study analyses keyed by the catalog's state (thread-safe; one computation per study at a time)."""

    def __init__(self, store: CatalogStore) -> None:
        self.store = store
        self._cache: OrderedDict[int, tuple[tuple, CachedAnalysis]] = OrderedDict()
        self._lock = threading.Lock()
        self._study_locks: dict[int, threading.Lock] = {}
        self._derived: OrderedDict[tuple, object] = OrderedDict()

    def fingerprint(self, study_id: int) -> tuple:
        return self.store.study_fingerprint(study_id)

    def get(self, study_id: int) -> CachedAnalysis:
        with self._lock:
            study_lock = self._study_locks.setdefault(study_id, threading.Lock())
        with study_lock:
            key = self.fingerprint(study_id)
            with self._lock:
                held = self._cache.get(study_id)
                if held is not None and held[0] == key:
                    self._cache.move_to_end(study_id)
                    return held[1]
            computed = self._compute(study_id)
            with self._lock:
                self._cache[study_id] = (key, computed)
                while len(self._cache) > CACHED_STUDIES:
                    self._cache.popitem(last=False)
            return computed

    def derived(self, study_id: int, name: str, compute: Callable[[], object]) -> object:
        """``compute()`` kept under the same catalog fingerprint as the study's analysis."""
        key = (study_id, name, self.fingerprint(study_id))
        with self._lock:
            if key in self._derived:
                return self._derived[key]
        value = compute()
        with self._lock:
            self._derived[key] = value
            while len(self._derived) > 4 * CACHED_STUDIES:
                self._derived.popitem(last=False)
        return value

    def _compute(self, study_id: int) -> CachedAnalysis:
        name = self.store.study(study_id).name
        analysis, _ = analyse_catalog_study(self.store.catalog, name)
        uid_of = {uid: k for k, uid in enumerate(analysis.sessions["session_id"])}
        return CachedAnalysis(analysis, uid_of)


def _finite(value) -> float | None:
    if value is None:
        return None
    value = float(value)
    return value if math.isfinite(value) else None


def records(frame: pd.DataFrame) -> list[dict]:
    """JSON-ready rows: NaN/NA as None, NumPy scalars as Python numbers."""
    out = []
    for row in frame.to_dict(orient="records"):
        clean = {}
        for key, value in row.items():
            if isinstance(value, np.generic):
                value = value.item()
            if isinstance(value, float):
                value = _finite(value)
            elif value is pd.NA:
                value = None
            clean[str(key)] = value
        out.append(clean)
    return out


def benchmark_rows(analysis: StudyAnalysis) -> list[dict]:
    return records(analysis.benchmarks)


def roc_points(per_participant: pd.DataFrame, metric: str, skilled: np.ndarray) -> dict | None:
    """ROC curve of one metric over participant medians (oriented so higher = better)."""
    from sklearn.metrics import roc_curve

    values = oriented(per_participant[metric], metric)
    keep = ~np.isnan(values)
    if keep.sum() < 2 or len(set(skilled[keep])) < 2:
        return None
    fpr, tpr, _ = roc_curve(skilled[keep], values[keep])
    return {"metric": metric, "fpr": fpr.round(4).tolist(), "tpr": tpr.round(4).tolist()}
