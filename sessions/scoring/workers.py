"""Scoring many sessions: in this process, or through Dask (a local cluster of worker processes,
or a running scheduler by address).

Workers compute (every metric and the per-stitch placement of one session, read from its folder)
and send back only those numbers; this process stores each session's scores as its result arrives,
so progress is reported and an interrupted run keeps what was done. A worker builds a task's tissue
model once (:func:`sessions.tasks.tissue_for` is cached per process, its factorisation on disk), not
once per session. Workers read sessions where the catalog says they are (a shared filesystem path:
VASCSIM_HOME on a mount every worker sees), or under ``data_root``: a path or any fsspec URL the
workers can reach.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

import pandas as pd

from sessions.catalog import Catalog, CatalogError
from sessions.config import data_home
from sessions.running.runner import ScoringInput, scoring_input, session_scores, store_scores


def _score_on_worker(
    what: ScoringInput, home: str | None
) -> tuple[str, dict[str, float], pd.DataFrame | None]:
    """Score one session where this worker can read it: a local path, a ``file://`` URL, or any
    other fsspec URL (the session's folder copied to a temporary folder first)."""
    import dataclasses
    import tempfile

    where = Path(home) if home else None
    if "://" not in what.directory:
        return what.uid, *session_scores(what, where)
    import fsspec

    filesystem, path = fsspec.core.url_to_fs(what.directory)
    protocols = filesystem.protocol if isinstance(filesystem.protocol, tuple) else (filesystem.protocol,)
    if {"file", "local"} & set(protocols):
        return what.uid, *session_scores(dataclasses.replace(what, directory=path), where)
    with tempfile.TemporaryDirectory(prefix="vascsim-score-") as folder:
        local = Path(folder) / Path(path.rstrip("/")).name
        filesystem.get(path.rstrip("/") + "/", str(local) + "/", recursive=True)
        return what.uid, *session_scores(dataclasses.replace(what, directory=str(local)), where)


def _relocated(inputs: list[ScoringInput], home: Path | None, data_root: str) -> list[ScoringInput]:
    """Each session's folder under ``data_root`` instead of the data directory (the same relative
    path): where the workers find the sessions (a mount or an fsspec URL)."""
    import dataclasses

    base = (home or data_home()).resolve()
    moved = []
    for what in inputs:
        try:
            relative = Path(what.directory).resolve().relative_to(base)
        except ValueError:
            raise CatalogError(
                f"session {what.uid} is stored outside the data directory ({what.directory}); "
                "it cannot be found under the data root"
            ) from None
        moved.append(dataclasses.replace(what, directory=f"{data_root.rstrip('/')}/{relative.as_posix()}"))
    return moved


def score_sessions(
    catalog: Catalog,
    uids: Sequence[str],
    home: Path | None = None,
    scheduler: str | None = None,
    workers: int | None = None,
    progress: Callable[[str], None] | None = None,
    data_root: str | None = None,
) -> dict[str, dict[str, float]]:
    """Score ``uids`` and store the results; returns {uid: metrics}. Without ``scheduler`` or
    ``workers`` in this process; ``workers=N`` on a local Dask cluster of N single-threaded worker
    processes; ``scheduler="tcp://host:8786"`` on a running cluster. ``progress(uid)`` after each.
    ``data_root``: where the sessions are read from instead of the data directory (a path the
    workers mount, or an fsspec URL such as ``s3://bucket/vascsim``; the same relative paths)."""
    inputs = [scoring_input(catalog, uid) for uid in uids]  # every id checked before any work
    if data_root is not None:
        inputs = _relocated(inputs, home, data_root)
    results: dict[str, dict[str, float]] = {}
    if scheduler is None and workers is None:
        for what in inputs:
            _, values, stitches = _score_on_worker(what, str(home) if home else None)
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
