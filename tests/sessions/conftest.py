"""CLI fixtures (catalog_url and open_catalog live in tests/conftest.py)."""

import pytest


@pytest.fixture
def home(tmp_path, catalog_url, monkeypatch):
    """VASCSIM_HOME and VASCSIM_DATABASE_URL for CLI tests."""
    folder = tmp_path / "home"
    monkeypatch.setenv("VASCSIM_HOME", str(folder))
    monkeypatch.setenv("VASCSIM_DATABASE_URL", catalog_url)
    return folder
