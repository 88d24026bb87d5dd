"""The dashboard figure of issue 9: server time per page and API call on a catalog of 10,000 sessions.

Run:  .venv/bin/python benchmarks/dashboard.py [--repeats 30] [--database-url postgresql://...]

Seeds a synthetic metrics-only study (20 experts + 80 trainees x 100 sessions =
10,000 sessions, 120,000 metric results) into a fresh catalog (SQLite in a temporary
VASCSIM_HOME by default), signs in as an admin and as a trainee, and requests every
page and API call ``--repeats`` times through the application in this process
(Starlette's TestClient: the server's whole work, no network). The first request of
each is reported apart (it computes the study analysis, which is then cached until
the catalog changes). Prints p50/p95 per request; target p95 <= 300 ms per page.
"""

from __future__ import annotations

import argparse
import re
import sys
import tempfile
import time
import uuid
from pathlib import Path

import numpy as np

# This script shares its name with the package it measures: keep its own folder off the path.
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).resolve().parent]


def _signed_in(client, username: str, password: str) -> None:
    page = client.get("/login")
    csrf = re.search(r'name="csrf_token" value="([^"]+)"', page.text).group(1)
    answer = client.post(
        "/login",
        data={"username": username, "password": password, "csrf_token": csrf},
        follow_redirects=False,
    )
    if answer.status_code != 303:
        raise SystemExit(f"sign-in as {username} failed: {answer.status_code}")


def _timed(client, url: str, repeats: int) -> tuple[float, list[float]]:
    start = time.perf_counter()
    first = client.get(url)
    cold = time.perf_counter() - start
    if first.status_code != 200:
        raise SystemExit(f"{url}: HTTP {first.status_code}: {first.text[:200]}")
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        client.get(url)
        times.append(time.perf_counter() - start)
    return cold, times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=30)
    parser.add_argument("--database-url", default=None, help="Catalog URL (default: SQLite in a temp dir).")
    args = parser.parse_args()

    from fastapi.testclient import TestClient
    from sqlalchemy import select

    from dashboard.app import create_app
    from dashboard.settings import DashboardSettings
    from sessions.catalog import Catalog
    from sessions.catalog.accounts import create_user, link_participant
    from sessions.catalog.models import Participant, Session
    from sessions.synthetic import seed_metrics_study

    with tempfile.TemporaryDirectory() as folder:
        home = Path(folder)
        url = args.database_url or f"sqlite:///{home / 'catalog.sqlite'}"
        catalog = Catalog(url)
        start = time.perf_counter()
        study_id = seed_metrics_study(catalog, f"bench-{uuid.uuid4().hex[:6]}", 20, 80, 100, seed=1)
        print(f"seeded 10,000 sessions in {time.perf_counter() - start:.1f} s ({catalog.display_url})")
        suffix = uuid.uuid4().hex[:6]
        with catalog.session() as orm:
            create_user(orm, f"admin-{suffix}", "benchmark-password", "admin")
            trainee = create_user(orm, f"trainee-{suffix}", "benchmark-password", "trainee")
            mine = orm.scalar(
                select(Participant).where(
                    Participant.study_id == study_id, Participant.group_label == "trainee"
                )
            )
            link_participant(orm, trainee, mine)
            participant_id = mine.id
            uid = orm.scalar(select(Session.uid).where(Session.participant_id == participant_id).limit(1))
        app = create_app(DashboardSettings(home=home, database_url=url), catalog)
        admin_urls = [
            "/",
            f"/studies/{study_id}",
            f"/studies/{study_id}/validity",
            f"/participants/{participant_id}",
            f"/sessions/{uid}",
            "/live",
            "/admin",
            "/api/studies",
            f"/api/studies/{study_id}",
            f"/api/studies/{study_id}/validity",
            f"/api/studies/{study_id}/validity.csv",
            f"/api/participants/{participant_id}/progress",
            f"/api/sessions?study_id={study_id}&limit=50",
            f"/api/sessions?study_id={study_id}&limit=50&offset=9900",
            f"/api/sessions/{uid}",
        ]
        trainee_urls = [f"/participants/{participant_id}", f"/sessions/{uid}", "/api/sessions?limit=50"]
        rows = []
        for username, urls in ((f"admin-{suffix}", admin_urls), (f"trainee-{suffix}", trainee_urls)):
            with TestClient(app) as client:
                _signed_in(client, username, "benchmark-password")
                for target in urls:
                    cold, times = _timed(client, target, args.repeats)
                    rows.append((username.split("-")[0], target, cold, times))
        catalog.close()
    print(f"{'as':8} {'request':58} {'first':>9} {'p50':>9} {'p95':>9}")
    worst = 0.0
    for who, target, cold, times in rows:
        p50, p95 = np.percentile(times, [50, 95]) * 1e3
        worst = max(worst, p95)
        print(f"{who:8} {target:58} {cold * 1e3:7.0f}ms {p50:7.1f}ms {p95:7.1f}ms")
    print(f"worst p95 {worst:.1f} ms over {args.repeats} repeats each (target <= 300 ms)")


if __name__ == "__main__":
    main()
