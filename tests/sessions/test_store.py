"""The catalog store's administration (issue 24): plain frozen values, errors by type, nothing made on a
refusal; the CLI and the dashboard both go through it (tests/dashboard/test_cli.py, test_access.py)."""

from __future__ import annotations

import dataclasses

import pytest
from sqlalchemy import select

from sessions.catalog import AlreadyExists, Catalog, NotFound, WrongState
from sessions.catalog.store import CatalogStore, UserRecord

PASSWORD = "correct horse battery"


@pytest.fixture
def store(catalog_url):
    """A store on SQLite and on PostgreSQL (each query must hold on both)."""
    catalog = Catalog(catalog_url)
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


def _session(catalog, code: str, status: str = "complete", note: str | None = None) -> str:
    """A catalogued session of participant ``code`` of the fixture's study (no streams)."""
    from sessions.catalog import new_uid, now
    from sessions.catalog.models import Annotation, Participant

    with catalog.session() as orm:
        participant_id = orm.scalar(select(Participant.id).where(Participant.code == code))
        task_id = catalog.task(orm, "closure", scenario="closure").id
    fields = dict(
        uid=new_uid(),
        participant_id=participant_id,
        task_id=task_id,
        device="scripted",
        clock="simulated",
        trial=None,
        status=status,
        started_at=now(),
        directory=f"/nowhere/{code}",
    )

    def annotate(orm, row) -> None:
        if note is not None:
            orm.add(Annotation(session_id=row.id, author="sup", time_s=1.5, text=note, created_at=now()))

    return catalog.add_session(fields, annotate).uid


def test_participants_are_created_listed_and_numbered_by_the_store(store):
    made = store.add_participant("course", "T03", level="expert", years_experience=12.0)
    assert (made.code, made.group, made.years, made.sessions, made.account) == (
        "T03",
        "expert",
        12.0,
        0,
        None,
    )
    with pytest.raises(AlreadyExists, match="participant 'T03' already exists in study 'course'"):
        store.add_participant("course", "T03")
    with pytest.raises(NotFound, match="no study named 'curse'; did you mean 'course'"):
        store.add_participant("curse", "T04")
    first, second = _session(store.catalog, "T01"), _session(store.catalog, "T01")
    assert [r.trial for r in store.sessions()] == [1, 2]  # trials numbered per participant and task
    assert [p.code for p in store.participants("course")] == ["T01", "T02", "T03"]
    assert store.participants("course")[0].sessions == 2
    summary = store.studies()[0]
    assert (summary.name, summary.participants, summary.sessions, summary.synthetic) == (
        "course",
        3,
        2,
        True,  # its sessions are scripted passes: synthetic data, though its participants are not
    )
    assert store.studies_of_sessions([first, second]) == ["course"]
    assert store.scorable_sessions("course") == [first, second]
    assert store.scorable_sessions("course", only_unscored=True) == [first, second]  # nothing scored yet


def test_deleting_a_session_removes_its_rows_and_names_its_folder(store):
    uid = _session(store.catalog, "T01", note="tremor at entry")
    assert store.session_facts(uid).annotations[0].text == "tremor at entry"
    assert store.delete_session(uid) == "/nowhere/T01"
    assert store.sessions() == []
    with pytest.raises(NotFound, match=f"no session {uid!r}"):
        store.session_facts(uid)


def test_a_reader_sees_only_what_their_role_allows(store):
    from sessions.catalog import Forbidden
    from sessions.catalog.store import Scope

    mine, theirs = _session(store.catalog, "T01", note="watch the angle"), _session(store.catalog, "T02")
    t01 = next(p for p in store.participants("course") if p.code == "T01")
    store.create_user("tom", PASSWORD, "trainee", ["course:T01"])
    trainee = Scope("trainee", frozenset({t01.id}))
    total, listed = store.visible_sessions(trainee)
    assert total == 1 and [r.uid for r in listed] == [mine]
    with pytest.raises(NotFound) as other:  # somebody else's session answers as one that does not exist
        store.session_facts(theirs, trainee)
    with pytest.raises(NotFound) as missing:
        store.session_facts("S-NOPE", trainee)
    assert str(other.value) == f"session {theirs!r} not found" and str(missing.value).endswith("not found")
    assert store.study(t01.study_id, trainee).name == "course"
    with pytest.raises(Forbidden, match="a whole study's data needs a different role"):
        store.study(t01.study_id, trainee, whole=True)
    assert [p.code for p in store.my_participants(trainee)] == ["T01"]
    assert [s.sessions for s in store.studies(trainee)] == [1]  # counts only their own
    researcher, supervisor = Scope("researcher"), Scope("supervisor")
    assert store.session_facts(mine, researcher).annotations[0].author is None  # pseudonymous
    assert store.session_facts(mine, supervisor).annotations[0].author == "sup"
    assert {p.account for p in store.study_participants(t01.study_id, researcher)} == {None}
    assert {p.account for p in store.study_participants(t01.study_id, supervisor)} == {"tom", None}
    assert store.sessions_by_status(t01.study_id, supervisor) == {"complete": 2}
    with pytest.raises(Forbidden):
        store.study(t01.study_id, Scope("nobody"))


def test_sign_in_round_trip_goes_through_the_store(store):
    from datetime import timedelta

    store.create_user("ada", PASSWORD, "admin")
    assert store.sign_in("ada", "wrong password!", timedelta(hours=1)) is None
    user, token, csrf = store.sign_in("ada", PASSWORD, timedelta(hours=1))
    assert store.signed_in(token) == (user, csrf)
    store.sign_out(token)
    assert store.signed_in(token) is None
