"""The demo's worker processes do not oversubscribe the cores: measured on 2 cores, two workers whose
CHOLMOD (OpenMP) and OpenBLAS each ran their own threads took the demo 141 s; one thread each, 100 s."""

from __future__ import annotations

import multiprocessing
from concurrent.futures import ProcessPoolExecutor

from sessions.demo import ONE_THREAD, one_thread_each


def _thread_counts() -> dict[str, int]:
    """What each numerical library loaded in this process would run on, after a column solve."""
    import numpy as np
    from threadpoolctl import threadpool_info

    from sessions.tasks import task_spec, tissue_for

    tissue = tissue_for(task_spec("wall-stitch"))
    tissue.base.solve_columns(np.array([0]))  # CHOLMOD and its OpenMP loaded and used
    return {f"{pool['internal_api']} {pool['filepath']}": pool["num_threads"] for pool in threadpool_info()}


def test_a_demo_worker_runs_every_numerical_library_on_one_thread(tmp_path, monkeypatch):
    """Whatever the parent's environment says (the suite's own workers run on one thread each)."""
    monkeypatch.setenv("VASCSIM_CACHE_DIR", str(tmp_path))
    for name in ONE_THREAD:
        monkeypatch.setenv(name, "2")
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(1, mp_context=context, initializer=one_thread_each) as pool:
        counts = pool.submit(_thread_counts).result(timeout=300)
    assert any(name.startswith("openmp") for name in counts), counts  # CHOLMOD's OpenMP is seen
    assert any(name.startswith("openblas") for name in counts), counts
    assert set(counts.values()) == {1}, counts
