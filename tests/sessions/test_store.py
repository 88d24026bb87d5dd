"""The catalog store's administration (issue 24): plain frozen values, errors by type, nothing made on a
refusal; the CLI and the dashboard both go through it (tests/dashboard/test_cli.py, test_access.py)."""

from __future__ import annotations

import dataclasses

import pytest

from sessions.catalog import AlreadyExists, Catalog, NotFound, WrongState
from sessions.store import CatalogStore, UserRecord

PASSWORD = "correct horse battery"


@pytest.fixture
def store(tmp_path):
    catalog = Catalog(f"sqlite:///{tmp_path / 'catalog.sqlite'}")
    with catalog.session() as orm:
        study = catalog.study(orm, "course", create=True)
        catalog.add_participant(orm, study, "T01", level="trainee")
        catalog.add_participant(orm, study, "T02", level="trainee")
    yield CatalogStore(catalog)
    catalog.close()


def test_accounts_are_plain_frozen_values_linked_by_code(store):
    made = store.create_user("tom", PASSWORD, "trainee", ["course:T01"])
    assert isinstance(made, UserRecord) and made.participants == ("course:T01",)
    with pytest.raises(dataclasses.FrozenInstanceError):
        made.role = "admin"
    relinked = store.set_user_participants(made.id, ["course:T02"])
    assert relinked.participants == ("course:T02",) and relinked.id == made.id
    assert [u.username for u in store.users()] == ["tom"]
    assert store.users()[0].as_dict()["participants"] == ["course:T02"]  # JSON-ready
    assert store.participant_codes() == ["course:T01", "course:T02"]


def test_refusals_are_typed_and_create_nothing(store):
    with pytest.raises(NotFound, match="no participant 'T99'"):
        store.create_user("eve", PASSWORD, "trainee", ["course:T99"])
    assert store.users() == []  # the unknown code made no account
    with pytest.raises(NotFound, match="no user 42"):
        store.change_user(42, role="admin")
    admin = store.create_user("ada", PASSWORD, "admin")
    with pytest.raises(WrongState, match="cannot deactivate or demote their own account"):
        store.change_user(admin.id, acting_user_id=admin.id, active=False)
    assert store.change_user(admin.id, acting_user_id=None, active=False).active is False
    store.create_study("second", "a description")
    with pytest.raises(AlreadyExists, match="study 'second' already exists"):
        store.create_study("second")


def test_station_tokens_are_shown_once_and_revoked(store):
    issued = store.issue_station_token("bench-1")
    token = issued["token"]
    assert len(token) >= 32 and [s.station for s in store.stations()] == ["bench-1"]
    assert "token" not in store.stations()[0].as_dict()  # listed without the token
    assert store.revoke_station_token(issued["id"]).revoked_at is not None


def test_sessions_are_listed_by_study_task_and_status(demo_catalog):
    catalog, _ = demo_catalog
    store = CatalogStore(catalog)
    every = store.sessions()
    assert len(every) == 16 and [r.id for r in every] == sorted(r.id for r in every)
    mine = store.sessions("synthetic-demo", status="complete")
    assert {r.study for r in mine} == {"synthetic-demo"} and len(mine) == 16
    assert store.sessions(task="no-such-task") == []
    with pytest.raises(NotFound, match="no study named 'synthetic-dem'; did you mean 'synthetic-demo'"):
        store.sessions("synthetic-dem")
    first = every[0]
    assert first.uid.startswith("S-") and first.started_at <= (first.ended_at or first.started_at)
