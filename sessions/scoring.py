"""Scoring many sessions: in this process, or through Dask (a local cluster of worker processes,
or a running scheduler by address).

Workers compute (every metric and the per-stitch placement of one session, read from its folder)
and send back only those numbers; this process stores each session's scores as its result arrives,
so progress is reported and an interrupted run keeps what was done. A worker builds a task's tissue
model once (:func:`sessions.tasks.tissue_for` is cached per process, its factorisation on disk), not
once per session. Workers read sessions where the catalog says they are: a shared filesystem path
(VASCSIM_HOME on a mount every worker sees) for a remote scheduler.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

import pandas as pd

from sessions.catalog import Catalog, CatalogError
from sessions.runner import ScoringInput, scoring_input, session_scores, store_scores


def _score_on_worker(
    what: ScoringInput, home: str | None
) -> tuple[str, dict[str, float], pd.DataFrame | None]:
    values, stitches = session_scores(what, Path(home) if home else None)
    return what.uid, values, stitches


def score_sessions(
    catalog: Catalog,
    uids: Sequence[str],
    home: Path | None = None,
    scheduler: str | None = None,
    workers: int | None = None,
    progress: Callable[[str], None] | None = None,
) -> dict[str, dict[str, float]]:
    """Score ``uids`` and store the results; returns {uid: metrics}. Without ``scheduler`` or
    ``workers`` in this process; ``workers=N`` on a local Dask cluster of N single-threaded worker
    processes; ``scheduler="tcp://host:8786"`` on a running cluster. ``progress(uid)`` after each."""
    inputs = [scoring_input(catalog, uid) for uid in uids]  # every id checked before any work
    results: dict[str, dict[str, float]] = {}
    if scheduler is None and workers is None:
        for what in inputs:
            values, stitches = session_scores(what, home)
            store_scores(catalog, what.uid, values, stitches)
            results[what.uid] = values
            if progress is not None:
                progress(what.uid)
        return results
    if workers is not None and workers < 1:
        raise CatalogError(f"workers must be at least 1; got {workers}")
    from dask.distributed import Client, LocalCluster, as_completed

    cluster = None
    try:
        if scheduler is None:
            cluster = LocalCluster(
                n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None
            )
            client = Client(cluster)
        else:
            client = Client(scheduler, timeout=10)
    except OSError as error:
        raise CatalogError(f"cannot reach the Dask scheduler {scheduler} ({error})") from error
    try:
        futures = [
            client.submit(_score_on_worker, what, str(home) if home else None, key=f"score-{what.uid}")
            for what in inputs
        ]
        for future in as_completed(futures):
            uid, values, stitches = future.result()
            store_scores(catalog, uid, values, stitches)
            results[uid] = values
            if progress is not None:
                progress(uid)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    return {uid: results[uid] for uid in uids}
