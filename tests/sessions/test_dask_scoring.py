"""Scoring through Dask from the CLI: a local two-worker cluster and a running scheduler give the
same stored results as scoring in this process; `report --workers` scores what is not yet scored."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner
from sqlalchemy import select, update

from sessions.catalog import Catalog
from sessions.catalog.models import MetricResult, Session, StitchResult
from sessions.cli import main
from sessions.demo import DEMO_STUDY


@pytest.fixture
def demo(tmp_path, copy_demo, monkeypatch):
    home = tmp_path / "home"
    url = copy_demo(home)
    monkeypatch.setenv("VASCSIM_HOME", str(home))
    monkeypatch.setenv("VASCSIM_DATABASE_URL", url)
    catalog = Catalog(url)
    yield catalog, home
    catalog.close()


def _stored(catalog) -> tuple[dict, dict]:
    with catalog.session() as orm:
        metrics = {
            (uid, m): v
            for uid, m, v in orm.execute(
                select(Session.uid, MetricResult.metric, MetricResult.value).join(
                    MetricResult, MetricResult.session_id == Session.id
                )
            )
        }
        stitches = {
            (uid, k, q): v
            for uid, k, q, v in orm.execute(
                select(Session.uid, StitchResult.stitch, StitchResult.quantity, StitchResult.value).join(
                    StitchResult, StitchResult.session_id == Session.id
                )
            )
        }
    return metrics, stitches


def _same(a: dict, b: dict) -> None:
    assert a.keys() == b.keys()
    keys = sorted(a)
    np.testing.assert_allclose(  # to the last bits: a worker's BLAS runs one thread, this process's several
        np.array([np.nan if a[k] is None else a[k] for k in keys], dtype=float),
        np.array([np.nan if b[k] is None else b[k] for k in keys], dtype=float),
        rtol=1e-9,
        atol=0,
    )


def test_two_local_workers_store_what_one_process_stores(demo):
    catalog, _ = demo
    runner = CliRunner()
    in_process = runner.invoke(main, ["score", "--study", DEMO_STUDY, "--json"])
    assert in_process.exit_code == 0, in_process.output
    reference = _stored(catalog)
    with catalog.session() as orm:
        orm.execute(update(MetricResult).values(value=-1.0))  # so the Dask run must write every value
        orm.execute(update(StitchResult).values(value=-1.0))
    on_dask = runner.invoke(main, ["score", "--study", DEMO_STUDY, "--workers", "2", "--json"])
    assert on_dask.exit_code == 0, on_dask.output
    assert json.loads(on_dask.stdout).keys() == json.loads(in_process.stdout).keys()
    for ours, theirs in zip(_stored(catalog), reference, strict=True):
        _same(ours, theirs)


def test_a_running_scheduler_and_report_scoring_what_is_stale(demo):
    from dask.distributed import LocalCluster

    catalog, home = demo
    reference = _stored(catalog)  # the demo scored every session in process
    with catalog.session() as orm:
        stale = list(orm.scalars(select(Session.id).order_by(Session.id).limit(3)))
        uids = list(orm.scalars(select(Session.uid).where(Session.id.in_(stale))))
        orm.execute(
            update(MetricResult).where(MetricResult.session_id.in_(stale)).values(registry_version="2")
        )
    runner = CliRunner()
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        done = runner.invoke(
            main, ["report", "--study", DEMO_STUDY, "--scheduler", cluster.scheduler_address]
        )
    assert done.exit_code == 0, done.output
    assert "older registry version" not in (home / "reports" / DEMO_STUDY / "report.md").read_text()
    metrics, _ = _stored(catalog)
    current = {k: v for k, v in metrics.items() if k[0] in uids}
    _same(current, {k: v for k, v in reference[0].items() if k[0] in uids})
    unreachable = runner.invoke(main, ["score", uids[0], "--scheduler", "tcp://127.0.0.1:9"])
    assert (
        unreachable.exit_code == 1
        and "cannot reach the Dask scheduler tcp://127.0.0.1:9" in unreachable.output
    )


def test_sessions_read_from_a_data_root_url(demo, tmp_path):
    """Workers find the sessions under --data-root: a mounted copy (file://) on two local workers, and
    an fsspec store (memory://) whose folders are copied to the worker first."""
    import shutil

    import fsspec

    catalog, home = demo
    reference = _stored(catalog)
    mounted = tmp_path / "mount"
    shutil.copytree(home / "sessions", mounted / "sessions")
    with catalog.session() as orm:
        uids = list(orm.scalars(select(Session.uid).order_by(Session.id).limit(4)))
        orm.execute(update(MetricResult).values(value=-1.0))
    shutil.rmtree(home / "sessions" / uids[0])  # only the mounted copy has it now
    runner = CliRunner()
    mount = runner.invoke(main, ["score", *uids, "--workers", "2", "--data-root", f"file://{mounted}"])
    assert mount.exit_code == 0, mount.output
    memory = fsspec.filesystem("memory")
    for uid in uids[2:]:
        for path in (mounted / "sessions" / uid).iterdir():
            memory.pipe(f"/store/sessions/{uid}/{path.name}", path.read_bytes())
    stored = runner.invoke(main, ["score", *uids[2:], "--data-root", "memory://store"])  # in process
    assert stored.exit_code == 0, stored.output
    metrics, _ = _stored(catalog)
    _same(
        {k: v for k, v in metrics.items() if k[0] in uids},
        {k: v for k, v in reference[0].items() if k[0] in uids},
    )
    missing = runner.invoke(main, ["score", uids[0]])  # without the data root: its folder is gone here
    assert missing.exit_code == 1 and uids[0] in missing.output and "Traceback" not in missing.output
