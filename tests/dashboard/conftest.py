"""A dashboard over a seeded catalog (SQLite and PostgreSQL), with one account per role."""

from __future__ import annotations

import contextlib
import socket
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import pytest
from fastapi.testclient import TestClient
from sqlalchemy import select

from dashboard.app import create_app
from dashboard.settings import DashboardSettings
from sessions.catalog.accounts import create_user, link_participant
from sessions.catalog.models import Participant, Session
from sessions.synthetic import seed_metrics_study

PASSWORD = "correct horse battery"
ROLES_UNDER_TEST = ("admin", "supervisor", "researcher", "trainee")


@dataclass
class Seeded:
    """The seeded catalog: ids a test needs, and the other trainee's data a trainee must never see."""

    app: object
    home: Path
    catalog: object
    study_id: int
    other_study_id: int
    own_participant: int
    other_participant: int
    own_sessions: list[str] = field(default_factory=list)
    other_sessions: list[str] = field(default_factory=list)
    other_code: str = ""


def seed_dashboard(catalog, home: Path, settings: dict | None = None) -> Seeded:
    study_id = seed_metrics_study(catalog, "course", 3, 4, 5, seed=3)
    other_study_id = seed_metrics_study(catalog, "other-course", 2, 2, 3, seed=4)
    with catalog.session() as orm:
        trainees = orm.scalars(
            select(Participant)
            .where(Participant.study_id == study_id, Participant.group_label == "trainee")
            .order_by(Participant.code)
        ).all()
        own, other = trainees[0], trainees[1]
        for role in ROLES_UNDER_TEST:
            user = create_user(orm, role, PASSWORD, role)
            if role == "trainee":
                link_participant(orm, user, own)
        other_user = create_user(orm, "trainee2", PASSWORD, "trainee")
        link_participant(orm, other_user, other)

        def uids(participant):
            return list(orm.scalars(select(Session.uid).where(Session.participant_id == participant.id)))

        seeded = Seeded(
            app=None,
            home=home,
            catalog=catalog,
            study_id=study_id,
            other_study_id=other_study_id,
            own_participant=own.id,
            other_participant=other.id,
            own_sessions=uids(own),
            other_sessions=uids(other),
            other_code=other.code,
        )
    seeded.app = create_app(
        DashboardSettings(home=home, database_url=catalog.url, **(settings or {})), catalog
    )
    return seeded


@pytest.fixture
def seeded(catalog_url, open_catalog, tmp_path) -> Seeded:
    return seed_dashboard(open_catalog(catalog_url), tmp_path / "home")


def sign_in(client: TestClient, username: str, password: str = PASSWORD) -> str:
    """Sign in through the JSON API; the client keeps the cookie. Returns the CSRF token."""
    answer = client.post("/api/login", json={"username": username, "password": password})
    assert answer.status_code == 200, answer.text
    return answer.json()["csrf_token"]


@pytest.fixture
def client_for(seeded):
    """client_for(role) -> (signed-in TestClient, CSRF token)."""
    clients = []

    def make(username: str):
        client = TestClient(seeded.app)
        client.__enter__()
        clients.append(client)
        return client, sign_in(client, username)

    yield make
    for client in clients:
        client.__exit__(None, None, None)


@contextlib.contextmanager
def running_server(app):
    """The app under a real uvicorn server with the slow-client guard, on 127.0.0.1 (a free port), in a
    thread; yields its base URL."""
    import uvicorn

    from dashboard.serving import ClientLimits, guarded_protocol

    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    server = uvicorn.Server(
        uvicorn.Config(
            app,
            host="127.0.0.1",
            port=port,
            log_level="warning",
            lifespan="on",
            http=guarded_protocol(ClientLimits()),  # as `vascsim serve` runs it
        )
    )
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    deadline = time.monotonic() + 20
    while not server.started:
        if time.monotonic() > deadline or not thread.is_alive():
            raise RuntimeError("the test server did not start")
        time.sleep(0.02)
    try:
        yield f"http://127.0.0.1:{port}"
    finally:
        server.should_exit = True
        thread.join(20)
