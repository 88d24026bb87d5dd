"""Each role's pages and API calls on SQLite and PostgreSQL: refusals hold, ids cannot be probed."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from tests.dashboard.conftest import PASSWORD


def error_of(answer) -> dict:
    body = answer.json()
    assert set(body) == {"error"} and set(body["error"]) == {"status", "message"}
    assert body["error"]["status"] == answer.status_code
    return body["error"]


def test_signed_out_requests_are_refused(seeded):
    with TestClient(seeded.app) as client:
        for url in (
            "/api/me",
            "/api/studies",
            f"/api/studies/{seeded.study_id}",
            f"/api/sessions/{seeded.own_sessions[0]}",
            "/api/users",
        ):
            answer = client.get(url)
            assert answer.status_code == 401, url
            assert error_of(answer)["message"] == "sign in first"
        page = client.get(f"/studies/{seeded.study_id}", follow_redirects=False)
        assert page.status_code == 303 and page.headers["location"].startswith("/login")


def test_trainee_sees_only_their_own_sessions_and_progress(seeded, client_for):
    client, _ = client_for("trainee")
    mine = client.get("/api/sessions?limit=500").json()
    assert sorted(item["uid"] for item in mine["items"]) == sorted(seeded.own_sessions)
    assert mine["total"] == len(seeded.own_sessions)
    studies = client.get("/api/studies").json()
    assert [s["id"] for s in studies] == [seeded.study_id]
    assert client.get(f"/api/participants/{seeded.own_participant}/progress").status_code == 200
    assert client.get(f"/participants/{seeded.own_participant}").status_code == 200
    assert client.get(f"/api/sessions/{seeded.own_sessions[0]}").status_code == 200
    # another trainee's data answers exactly like data that does not exist
    for url in (
        f"/api/participants/{seeded.other_participant}/progress",
        f"/api/sessions/{seeded.other_sessions[0]}",
        f"/api/sessions/{seeded.other_sessions[0]}/signals",
        f"/api/sessions/{seeded.other_sessions[0]}/video",
        f"/api/sessions/{seeded.other_sessions[0]}/files/samples.parquet",
    ):
        answer = client.get(url)
        assert answer.status_code == 404, url
        assert "not found" in error_of(answer)["message"]
    assert client.get(f"/sessions/{seeded.other_sessions[0]}").status_code == 404
    assert client.get(f"/participants/{seeded.other_participant}").status_code == 404
    # whole-study views, other studies, administration and the live view are not for trainees
    assert client.get(f"/api/studies/{seeded.study_id}").status_code == 403
    assert client.get(f"/api/studies/{seeded.study_id}/validity").status_code == 403
    # refused by role before any lookup: the same answer for another study and for none at all
    assert client.get(f"/api/studies/{seeded.other_study_id}").status_code == 403
    assert client.get("/api/studies/999999").status_code == 403
    for url in ("/api/users", "/api/stations", "/api/live", "/admin", "/live"):
        assert client.get(url).status_code == 403, url


def test_guessing_ids_finds_nothing_of_anyone_else(seeded, client_for):
    client, _ = client_for("trainee")
    with seeded.catalog.session() as orm:
        from sqlalchemy import select

        from sessions.catalog.models import Participant, Session

        every_participant = list(orm.scalars(select(Participant.id)))
        every_session = list(orm.scalars(select(Session.uid)))
    for participant_id in [*every_participant, max(every_participant) + 1]:
        expected = 200 if participant_id == seeded.own_participant else 404
        assert client.get(f"/api/participants/{participant_id}/progress").status_code == expected
    for impossible in (0, -1, 2**63):  # not an id at all: refused before any lookup
        assert client.get(f"/api/participants/{impossible}/progress").status_code == 422
    for uid in every_session:
        expected = 200 if uid in seeded.own_sessions else 404
        assert client.get(f"/api/sessions/{uid}").status_code == expected


def test_researcher_sees_studies_pseudonymously_and_nothing_administrative(seeded, client_for):
    client, _ = client_for("researcher")
    overview = client.get(f"/api/studies/{seeded.study_id}").json()
    assert {p["code"] for p in overview["participants"]} >= {seeded.other_code}
    assert all("account" not in p for p in overview["participants"])  # who is behind a code stays hidden
    assert client.get(f"/api/studies/{seeded.study_id}/validity").status_code == 200
    assert client.get(f"/api/sessions/{seeded.other_sessions[0]}").status_code == 200
    for url in ("/api/users", "/api/stations", "/api/live", "/admin", "/live"):
        assert client.get(url).status_code == 403, url


def test_supervisor_sees_accounts_and_live_view_but_cannot_administer(seeded, client_for):
    client, csrf = client_for("supervisor")
    overview = client.get(f"/api/studies/{seeded.study_id}").json()
    accounts = {p["code"]: p["account"] for p in overview["participants"]}
    assert accounts[seeded.other_code] == "trainee2"
    assert client.get("/api/live").status_code == 200
    # issue 44, seen 10: the live page's times carry their zone
    from sqlalchemy import select, update

    from sessions.catalog.models import Session

    uid = seeded.other_sessions[0]
    with seeded.catalog.session() as orm:
        status = orm.scalar(select(Session.status).where(Session.uid == uid))
        orm.execute(update(Session).where(Session.uid == uid).values(status="running"))
    try:
        page = client.get("/live").text
        line = next(part for part in page.split("<li>") if uid in part)
        assert " UTC)" in line and "since 20" in line
    finally:
        with seeded.catalog.session() as orm:
            orm.execute(update(Session).where(Session.uid == uid).values(status=status))
    assert client.get("/api/users").status_code == 403
    answer = client.post(
        "/api/users",
        json={"username": "mallory", "password": PASSWORD, "role": "admin"},
        headers={"X-CSRF-Token": csrf},
    )
    assert answer.status_code == 403


def test_admin_manages_users_tokens_and_studies(seeded, client_for):
    client, csrf = client_for("admin")
    headers = {"X-CSRF-Token": csrf}
    created = client.post(
        "/api/users",
        json={"username": "newcomer", "password": PASSWORD, "role": "trainee", "participant_ids": []},
        headers=headers,
    )
    assert created.status_code == 201, created.text
    assert (
        client.post(
            "/api/users",
            json={"username": "newcomer", "password": PASSWORD, "role": "trainee"},
            headers=headers,
        ).json()["error"]["message"]
        == "user 'newcomer' already exists"
    )
    weak = client.post(
        "/api/users", json={"username": "weak", "password": "short", "role": "trainee"}, headers=headers
    )
    assert weak.status_code == 422 and "at least 10 characters" in error_of(weak)["message"]
    me = client.get("/api/me").json()
    users = {u["username"]: u["id"] for u in client.get("/api/users").json()}
    refused = client.patch(f"/api/users/{users[me['username']]}", json={"active": False}, headers=headers)
    assert refused.status_code == 409
    token = client.post("/api/stations", json={"station": "bench-1"}, headers=headers)
    assert token.status_code == 201 and len(token.json()["token"]) >= 40
    listed = client.get("/api/stations").json()
    assert [s["station"] for s in listed] == ["bench-1"] and "token" not in listed[0]
    study = client.post("/api/studies", json={"name": "spring course"}, headers=headers)
    assert study.status_code == 201
    assert client.post("/api/studies", json={"name": "spring course"}, headers=headers).status_code == 409


@pytest.mark.parametrize("role", ["supervisor", "researcher", "trainee"])
def test_only_admins_reach_administration(seeded, client_for, role):
    client, csrf = client_for(role)
    headers = {"X-CSRF-Token": csrf}
    assert client.post("/api/stations", json={"station": "x"}, headers=headers).status_code == 403
    assert client.delete("/api/stations/1", headers=headers).status_code == 403
    assert client.patch("/api/users/1", json={"active": False}, headers=headers).status_code == 403
    assert client.post("/api/studies", json={"name": "x"}, headers=headers).status_code == 403


def test_deactivating_an_account_ends_its_sign_ins_for_good(seeded, client_for):
    """Issue 23 (7): re-activating a deactivated account brought back its old sign-ins."""
    admin, csrf = client_for("admin")
    trainee, _ = client_for("trainee")
    assert trainee.get("/api/me").status_code == 200
    users = {u["username"]: u["id"] for u in admin.get("/api/users").json()}
    headers = {"X-CSRF-Token": csrf}
    assert (
        admin.patch(f"/api/users/{users['trainee']}", json={"active": False}, headers=headers).status_code
        == 200
    )
    assert trainee.get("/api/me").status_code == 401
    assert (
        admin.patch(f"/api/users/{users['trainee']}", json={"active": True}, headers=headers).status_code
        == 200
    )
    assert trainee.get("/api/me").status_code == 401  # the old cookie stays dead; a new sign-in is needed


def test_domain_errors_map_to_http_statuses_by_type_never_by_wording():
    """Issue 24: NotFound 404, Forbidden 403, AlreadyExists / WrongState 409, the rest 400; a message
    that happens to start with "no " is not a 404 (it was: "no free trial number" answered 404)."""
    from dashboard.errors import status_of
    from sessions.catalog import AlreadyExists, CatalogError, Forbidden, NotFound, WrongState
    from sessions.catalog.accounts import AccountConflict, AccountNotFound

    assert status_of(NotFound("study", "x")) == 404
    assert status_of(AccountNotFound("user", "nobody")) == 404
    assert status_of(Forbidden("this station may not write that session")) == 403
    assert status_of(AlreadyExists("study 'x' exists")) == status_of(AccountConflict("taken")) == 409
    assert status_of(WrongState("no free trial number after 20 attempts")) == 409
    assert status_of(CatalogError("no good: the request is malformed")) == 400


def test_a_refused_page_keeps_the_navigation_and_sign_out(seeded, client_for):
    """Issue 25, seen: the 403 page dropped the navigation and Sign out."""
    client, _ = client_for("trainee")
    refused = client.get("/admin")
    assert refused.status_code == 403
    assert 'id="sign-out"' in refused.text and 'href="/">Home</a>' in refused.text
    assert "needs a different role" in refused.text


def test_admin_links_trainee_accounts_by_study_and_code_and_refuses_what_does_not_resolve(seeded, client_for):
    """Issue 25, seen: linking asked for internal ids ("e.g. 12, 13"), and typing the code a supervisor
    knows created the account with no link and no error. Now: STUDY:CODE, refused when it does not
    resolve (and no account is made), links editable later, codes shown."""
    client, csrf = client_for("admin")

    def form(url, **fields):
        return client.post(url, data={"csrf_token": csrf, **fields})

    account = {"username": "ana", "password": PASSWORD, "role": "trainee"}
    unknown = form("/admin/users", **account, participants="course:T9999")
    assert (
        unknown.status_code == 404
        and "no participant &#39;T9999&#39; in study &#39;course&#39;" in unknown.text
    )
    bare = form("/admin/users", **account, participants="T0003")
    assert bare.status_code == 400 and "must be written STUDY:CODE" in bare.text
    no_role = form("/admin/users", **{**account, "role": ""}, participants="course:T0003")
    assert no_role.status_code == 422 and "choose a role" in no_role.text
    assert "ana" not in {u["username"] for u in client.get("/api/users").json()}  # nothing was made
    made = form("/admin/users", **account, participants="course:T0003")
    assert made.status_code == 200 and "created user &#39;ana&#39;" in made.text
    users = {u["username"]: u for u in client.get("/api/users").json()}
    assert users["ana"]["participants"] == ["course:T0003"]
    relinked = form(f"/admin/users/{users['ana']['id']}/participants", participants="course:T0004")
    assert relinked.status_code == 200, relinked.text
    users = {u["username"]: u for u in client.get("/api/users").json()}
    assert users["ana"]["participants"] == ["course:T0004"]  # T0003 unlinked
    page = client.get("/admin").text
    assert 'value="course:T0004"' in page and "e.g. 12, 13" not in page
    assert '<option value="" disabled selected>choose a role</option>' in page  # never admin by default


def test_needs_attention_says_why_and_tells_retention_from_practice():
    """Issue 25, seen: all six trainees listed, three of them proficient, because each one's latest
    session was the retention trial; and a failed retention (numpy's False) was never listed."""
    import numpy as np
    import pandas as pd

    from dashboard.queries import _attention_reasons

    trainees = pd.DataFrame(
        {
            "proficient": [True, False],
            "trials_to_proficiency": [5.0, np.nan],
            "practice_sessions": [6, 6],
            "retention_passed": np.array([False, True]),
        },
        index=["T04", "T01"],
    )
    proficient = {"code": "T04", "latest_trial": 7, "latest_phase": "retention", "latest_passed": False}
    assert _attention_reasons(proficient, trainees) == [
        "the delayed retention session was worse than the benchmark"
    ]
    assert proficient["proficient"] is True and proficient["proficient_at"] == 5
    struggling = {"code": "T01", "latest_trial": 6, "latest_phase": "practice", "latest_passed": False}
    assert _attention_reasons(struggling, trainees) == [
        "not proficient after 6 practice sessions",
        "the latest practice session (trial 6) was worse than the benchmark",
    ]


def test_researchers_see_raters_as_stable_pseudonyms(seeded, client_for):
    """Issue 45, seen 8: after a supervisor rated a session in the dashboard, the researcher's
    /api/sessions/{uid}/ratings and the session page named the rater's account ("supervisor")."""
    supervisor, csrf = client_for("supervisor")
    from metrics.instruments import INSTRUMENTS

    uid = seeded.other_sessions[0]
    scores = {"instrument": "GRS", "scores": {name: 3 for name in INSTRUMENTS["GRS"].item_names}}
    stored = supervisor.post(f"/api/sessions/{uid}/ratings", json=scores, headers={"X-CSRF-Token": csrf})
    assert stored.status_code == 201, stored.text
    assert [r["rater"] for r in supervisor.get(f"/api/sessions/{uid}/ratings").json()] == ["supervisor"]
    researcher, _ = client_for("researcher")
    for _ in range(2):  # the same name every time it is asked
        seen = researcher.get(f"/api/sessions/{uid}/ratings").json()
        assert [r["rater"] for r in seen] == ["rater 1"]
    page = researcher.get(f"/sessions/{uid}").text
    assert "rater 1" in page and ">supervisor<" not in page
