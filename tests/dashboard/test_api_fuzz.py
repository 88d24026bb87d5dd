"""The OpenAPI document fuzzed with schemathesis: no 500s, the one error shape, and a trainee never
receives another participant's data, whatever the request."""

from __future__ import annotations

import re

import pytest
import schemathesis
from hypothesis import HealthCheck, given, settings

from tests.dashboard.conftest import seed_dashboard, sign_in

EXAMPLES = 25
ERROR_SHAPE = re.compile(r'^\{"error":\{"status":\d{3},"message":".*"\}\}$', re.S)


@pytest.fixture
def site(tmp_path, open_catalog):
    return seed_dashboard(open_catalog(f"sqlite:///{tmp_path / 'catalog.sqlite'}"), tmp_path / "home")


def _operations(site):
    schema = schemathesis.openapi.from_asgi("/api/openapi.json", site.app).exclude(path="/api/logout")
    operations = [result.ok() for result in schema.get_all_operations()]
    assert len(operations) >= 20  # every API route is in the document
    return operations


def _headers(site, username: str) -> dict[str, str]:
    from fastapi.testclient import TestClient

    with TestClient(site.app) as client:
        csrf = sign_in(client, username)
        cookie = "; ".join(f"{k}={v}" for k, v in client.cookies.items())
    return {"Cookie": cookie, "X-CSRF-Token": csrf}


def _documented(site) -> dict[tuple[str, str], set[int]]:
    """Per (METHOD, path template): the statuses the OpenAPI document says the route answers."""
    from fastapi.testclient import TestClient

    with TestClient(site.app) as client:
        document = client.get("/api/openapi.json").json()
    return {
        (method.upper(), path): {int(status) for status in operation["responses"]}
        for path, item in document["paths"].items()
        for method, operation in item.items()
    }


def _check(response, documented: set[int]) -> None:
    assert response.status_code < 500, (response.status_code, response.text[:300])
    # issue 23 (7): every answer is documented (409s included); 405 is the router's, not the route's
    assert response.status_code in documented | {405}, (response.status_code, response.text[:300])
    kind = (response.headers.get("content-type") or [""])[0]  # schemathesis keeps header values as lists
    if response.status_code >= 400 and kind.startswith("application/json"):
        assert ERROR_SHAPE.match(response.text), response.text[:300]


def _fuzz(site, username: str, check) -> int:
    """Every operation with generated requests (cookie + CSRF token of ``username``); the number of calls."""
    headers = _headers(site, username)
    statuses = _documented(site)
    calls = 0
    for operation in _operations(site):

        @settings(
            max_examples=EXAMPLES, deadline=None, database=None, suppress_health_check=list(HealthCheck)
        )
        @given(case=operation.as_strategy())
        def run(case):
            nonlocal calls
            calls += 1
            response = case.call(headers=headers)
            _check(response, statuses[(case.method.upper(), case.operation.path)])
            check(case, response)

        run()
    return calls


def test_documented_constraints_are_the_enforced_ones(site):
    """Issue 23 (7): the OpenAPI document states the account rules the server applies, and a study
    with no scored sessions is a documented 409, not an undocumented 400."""
    from fastapi.testclient import TestClient

    from sessions.catalog.accounts import MIN_PASSWORD_LENGTH, STATION_PATTERN, USERNAME_PATTERN

    with TestClient(site.app) as client:
        schemas = client.get("/api/openapi.json").json()["components"]["schemas"]
        csrf = {"X-CSRF-Token": sign_in(client, "admin")}
        assert schemas["NewUser"]["properties"]["password"]["minLength"] == MIN_PASSWORD_LENGTH
        assert schemas["NewUser"]["properties"]["username"]["pattern"] == USERNAME_PATTERN.pattern
        assert schemas["NewStation"]["properties"]["station"]["pattern"] == STATION_PATTERN.pattern
        short, enough = "p" * (MIN_PASSWORD_LENGTH - 1), "p" * MIN_PASSWORD_LENGTH
        for password, status in ((short, 422), (enough, 201)):
            created = client.post(
                "/api/users",
                json={"username": "edge", "password": password, "role": "researcher"},
                headers=csrf,
            )
            assert created.status_code == status, created.text
        again = client.post(
            "/api/users", json={"username": "edge", "password": enough, "role": "researcher"}, headers=csrf
        )
        assert again.status_code == 409 and again.json()["error"]["message"] == "user 'edge' already exists"
        empty = client.post("/api/studies", json={"name": "empty"}, headers=csrf).json()["id"]
        for path in (f"/api/studies/{empty}/validity", f"/api/studies/{empty}/validity.csv"):
            answer = client.get(path)
            assert answer.status_code == 409 and "has no scored sessions" in answer.text, answer.text
        documented = _documented(site)
        for key in (
            ("GET", "/api/studies/{study_id}/validity"),
            ("POST", "/api/users"),
            ("PATCH", "/api/users/{user_id}"),
            ("POST", "/api/stations"),
            ("POST", "/api/studies"),
            ("GET", "/api/live/sessions/{uid}"),
        ):
            assert 409 in documented[key], key


def test_api_as_admin_never_fails(site):
    assert _fuzz(site, "admin", lambda case, response: None) > 200


def test_api_as_trainee_never_leaks(site):
    def no_other_data(case, response):
        for uid in site.other_sessions:
            assert uid not in response.text, (case.path, uid)
        assert site.other_code not in response.text, case.path

    assert _fuzz(site, "trainee", no_other_data) > 200
