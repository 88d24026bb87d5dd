"""The catalog on SQLite and PostgreSQL: migrations match the models, concurrent writers, the demo flow."""

import multiprocessing

import numpy as np
import pandas as pd
import pytest
from alembic.autogenerate import compare_metadata
from alembic.migration import MigrationContext
from sqlalchemy import func, select

from metrics import compute_session_metrics
from sessions.catalog import Catalog, CatalogError
from sessions.catalog.models import Base, Participant, Session
from sessions.demo import PRIMARY_METRICS, DemoSize, run_demo
from sessions.tasks import session_tissue
from tests.conftest import REDUCED_DEMO_SIZE


def test_migrations_match_the_models(catalog_url, open_catalog):
    catalog = open_catalog(catalog_url)
    with catalog.engine.connect() as connection:
        context = MigrationContext.configure(connection)
        differences = compare_metadata(context, Base.metadata)
    assert differences == []
    open_catalog(catalog_url)  # upgrading an up-to-date catalog is a no-op


def _writer(url, prefix, count):
    catalog = Catalog(url)
    for k in range(count):
        with catalog.session() as orm:
            study = catalog.study(orm, "shared", create=True) if k == 0 and prefix == "a" else None
            study = study or catalog.study(orm, "shared")
            catalog.add_participant(orm, study, f"{prefix}{k:03d}", level="trainee")
    catalog.close()


def test_two_processes_writing_at_once_lose_nothing(catalog_url, open_catalog):
    catalog = open_catalog(catalog_url)
    with catalog.session() as orm:
        catalog.study(orm, "shared", create=True)
    context = multiprocessing.get_context("spawn")
    workers = [context.Process(target=_writer, args=(catalog_url, p, 40)) for p in ("a", "b")]
    for worker in workers:
        worker.start()
    for worker in workers:
        worker.join(120)
        assert worker.exitcode == 0
    with catalog.session() as orm:
        assert orm.scalar(select(func.count(Participant.id))) == 80


def test_unknown_names_are_catalog_errors(catalog_url, open_catalog):
    catalog = open_catalog(catalog_url)
    with catalog.session() as orm:
        study = catalog.study(orm, "s", create=True)
        with pytest.raises(CatalogError, match="no participant 'X9'"):
            catalog.participant(orm, study, "X9")
        with pytest.raises(CatalogError, match="no study named 'nope'"):
            catalog.study(orm, "nope")


def test_bad_urls_are_one_line_errors(tmp_path):
    with pytest.raises(CatalogError, match="not valid"):
        Catalog("not a url")
    with pytest.raises(CatalogError, match="only sqlite and postgresql"):
        Catalog("mysql://localhost/x")
    with pytest.raises(CatalogError, match="cannot open the catalog"):
        Catalog("postgresql://postgres@127.0.0.1:5432/database_that_does_not_exist")


@pytest.mark.slow
@pytest.mark.exclusive  # the demo's two workers want both cores (63 s sharing them with the other worker)
@pytest.mark.parametrize("catalog_url", ["postgresql"], indirect=True)
def test_reduced_demo_on_postgresql_report_matches_the_stored_streams(catalog_url, tmp_path, open_catalog):
    catalog = open_catalog(catalog_url)
    result = run_demo(catalog, tmp_path, DemoSize(**REDUCED_DEMO_SIZE))
    _report_matches_the_stored_streams(catalog, result, tmp_path)


def test_reduced_demo_on_sqlite_report_matches_the_stored_streams(demo_template, open_catalog):
    """The shared reduced demo (tests/conftest.py) ran on SQLite."""
    home, result = demo_template
    catalog = open_catalog(f"sqlite:///{home / 'catalog.sqlite'}")
    _report_matches_the_stored_streams(catalog, result, home)


def _report_matches_the_stored_streams(catalog, result, tmp_path):
    assert result.sessions == 2 * 2 + 3 * 4
    with catalog.session() as orm:
        rows = orm.execute(select(Session.uid, Session.directory, Session.status)).all()
    assert {r.status for r in rows} == {"complete"}
    direct = (
        compute_session_metrics(
            [r.directory for r in rows], tissue=lambda streams: session_tissue(streams, tmp_path / "cache")
        )
        .set_index("session_id")
        .sort_index()
    )
    stored = (
        pd.read_csv(result.report.parent / "tables" / "session_metrics.csv")
        .rename(columns=lambda header: header.split(" [")[0])  # "path_length [m]": SI, unit in the header
        .set_index("session_id")
        .sort_index()
    )
    metric_columns = [
        c
        for c in direct.columns
        if c not in ("participant_id", "label", "trial", "phase", "synthetic", "task")
    ]
    np.testing.assert_allclose(
        stored[metric_columns].to_numpy(float), direct[metric_columns].to_numpy(float), rtol=1e-9
    )
    tissue_metrics = ["high_stress_area", "stress_concentration", "peak_stretch", "time_above_strain_limit"]
    assert np.isfinite(stored[tissue_metrics].to_numpy(float)).all()  # derived for every simulator session
    assert set(stored["participant_id"]) == {"E01", "E02", "T01", "T02", "T03"}
    assert stored["synthetic"].all()
    assert "Synthetic data" in result.report.read_text()
    # the validity table in the report equals the one computed from the direct metrics
    validity = pd.read_csv(result.report.parent / "tables" / "construct_validity.csv")
    assert set(validity["metric"]) == set(PRIMARY_METRICS)  # the declared primary set, and only it
