"""A replay rendered from the session page: started by staff over the API (CSRF-checked), one at a
time, its progress readable, the finished video the same file `vascsim replay --vs-group experts`
writes, then served on the session page."""

from __future__ import annotations

import time

from fastapi.testclient import TestClient
from sqlalchemy import select

from dashboard.app import create_app
from dashboard.settings import DashboardSettings
from sessions.catalog.accounts import create_user, link_participant
from sessions.catalog.models import Participant, Session
from tests.dashboard.conftest import sign_in

PASSWORD = "correct horse battery"


def test_staff_render_a_replay_with_progress_one_at_a_time(demo_catalog):
    catalog, home = demo_catalog
    with catalog.session() as orm:
        trainee = orm.scalar(select(Participant).where(Participant.code == "T01"))
        first, second = orm.scalars(
            select(Session.uid).where(Session.participant_id == trainee.id).order_by(Session.trial).limit(2)
        ).all()
        create_user(orm, "supervisor", PASSWORD, "supervisor")
        link_participant(orm, create_user(orm, "trainee", PASSWORD, "trainee"), trainee)
    app = create_app(DashboardSettings(home=home, database_url=catalog.url), catalog)
    with TestClient(app) as client:
        token = sign_in(client, "trainee", PASSWORD)
        assert (
            client.post(f"/api/sessions/{first}/replay", headers={"X-CSRF-Token": token}).status_code == 403
        )
    with TestClient(app) as client:
        token = sign_in(client, "supervisor", PASSWORD)
        assert "Render the replay" in client.get(f"/sessions/{first}").text
        assert client.get(f"/api/sessions/{first}/replay").json()["state"] == "none"
        assert client.post(f"/api/sessions/{first}/replay").status_code == 403  # no CSRF token
        started = client.post(f"/api/sessions/{first}/replay", headers={"X-CSRF-Token": token})
        assert started.status_code == 202 and started.json()["state"] == "rendering"
        busy = client.post(f"/api/sessions/{second}/replay", headers={"X-CSRF-Token": token})
        assert busy.status_code == 409 and first in busy.json()["error"]["message"]
        seen = []
        deadline = time.monotonic() + 300
        while time.monotonic() < deadline:
            status = client.get(f"/api/sessions/{first}/replay").json()
            seen.append(status["frames_done"])
            if status["state"] != "rendering":
                break
            time.sleep(0.5)
        assert status["state"] == "ready", status
        assert max(seen) > 0  # progress was reported along the way
        assert (home / "replays" / f"{first}-vs.mp4").is_file()  # the CLI's file
        assert not list((home / "replays").glob(".*part*"))
        video = client.get(f"/api/sessions/{first}/video")
        assert video.status_code == 200 and video.headers["content-type"] == "video/mp4"
        assert 'id="replay"' in client.get(f"/sessions/{first}").text
