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


def _check(response) -> None:
    assert response.status_code < 500, (response.status_code, response.text[:300])
    kind = (response.headers.get("content-type") or [""])[0]  # schemathesis keeps header values as lists
    if response.status_code >= 400 and kind.startswith("application/json"):
        assert ERROR_SHAPE.match(response.text), response.text[:300]


def _fuzz(site, username: str, check) -> int:
    """Every operation with generated requests (cookie + CSRF token of ``username``); the number of calls."""
    headers = _headers(site, username)
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
            _check(response)
            check(case, response)

        run()
    return calls


def test_api_as_admin_never_fails(site):
    assert _fuzz(site, "admin", lambda case, response: None) > 200


def test_api_as_trainee_never_leaks(site):
    def no_other_data(case, response):
        for uid in site.other_sessions:
            assert uid not in response.text, (case.path, uid)
        assert site.other_code not in response.text, case.path

    assert _fuzz(site, "trainee", no_other_data) > 200
