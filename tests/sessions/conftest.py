"""Catalog fixtures: every catalog test runs on SQLite and on the PostgreSQL server at 127.0.0.1:5432."""

import os
import uuid

import psycopg
import pytest

POSTGRES_ADMIN = os.environ.get("VASCSIM_TEST_POSTGRES", "postgresql://postgres@127.0.0.1:5432/test")


@pytest.fixture(params=["sqlite", "postgresql"])
def catalog_url(request, tmp_path):
    if request.param == "sqlite":
        yield f"sqlite:///{tmp_path / 'catalog.sqlite'}"
        return
    name = f"vascsim_{uuid.uuid4().hex[:12]}"
    with psycopg.connect(POSTGRES_ADMIN, autocommit=True) as admin:
        admin.execute(f'CREATE DATABASE "{name}"')
    base = POSTGRES_ADMIN.rsplit("/", 1)[0]
    yield f"{base}/{name}"
    with psycopg.connect(POSTGRES_ADMIN, autocommit=True) as admin:
        admin.execute(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)')


@pytest.fixture
def home(tmp_path, catalog_url, monkeypatch):
    """VASCSIM_HOME and VASCSIM_DATABASE_URL for CLI tests."""
    folder = tmp_path / "home"
    monkeypatch.setenv("VASCSIM_HOME", str(folder))
    monkeypatch.setenv("VASCSIM_DATABASE_URL", catalog_url)
    return folder


@pytest.fixture
def open_catalog():
    """Opens catalogs and disposes their connection pools at teardown (no connection left to the GC)."""
    from sessions.catalog import Catalog

    opened = []

    def factory(url):
        catalog = Catalog(url)
        opened.append(catalog)
        return catalog

    yield factory
    for catalog in opened:
        catalog.close()
