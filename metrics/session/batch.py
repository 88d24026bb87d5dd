"""Batch metrics over many stored sessions on Dask: a local cluster by default, a remote one by address.

Each task opens one session's Parquet files and computes its row, so only rows travel
back to the client; the result equals ``compute_session_metrics`` on the same
sessions, in the same order.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

import pandas as pd

from metrics.session.compute import compute_session_metrics


def _row(path: str, names: list[str] | None) -> pd.DataFrame:
    return compute_session_metrics([path], names)


def compute_metrics_dask(
    session_dirs: Sequence[str | Path],
    scheduler: str | None = None,
    n_workers: int = 2,
    metrics: Sequence[str] | None = None,
    progress: Callable[[int], None] | None = None,
) -> pd.DataFrame:
    """Per-session metrics of recorded session directories, computed by Dask workers.

    scheduler: None starts a local cluster of ``n_workers`` single-threaded worker
    processes for the call; ``"tcp://host:8786"`` uses a running scheduler.
    """
    from dask.distributed import Client, LocalCluster, as_completed

    paths = [str(Path(p).resolve()) for p in session_dirs]
    names = list(metrics) if metrics is not None else None
    cluster = None
    if scheduler is None:
        cluster = LocalCluster(
            n_workers=n_workers, threads_per_worker=1, processes=True, dashboard_address=None
        )
        client = Client(cluster)
    else:
        client = Client(scheduler)
    try:
        futures = client.map(_row, paths, names=names, key=[f"metrics-{i}" for i in range(len(paths))])
        if progress is not None:
            for _ in as_completed(futures):
                progress(1)
        rows = client.gather(futures)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    if not rows:
        return compute_session_metrics([], names)
    frame = pd.concat(rows, ignore_index=True)
    frame.attrs.update(rows[0].attrs)
    return frame
