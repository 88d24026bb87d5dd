"""Re-running the demo (issue 25): trainee accounts stay linked to the participant codes they had, an
account whose participant the new demo lacks is reported, and the old sessions' replay videos go with
their sessions instead of lingering as orphans."""

from __future__ import annotations

import pytest
from sqlalchemy import select

from sessions.catalog import Catalog
from sessions.catalog.accounts import create_user, link_participant
from sessions.catalog.models import Participant, Session, User
from sessions.cli.demo import rerun_lines
from sessions.demo import DemoSize, run_demo


@pytest.mark.slow
def test_a_rerun_keeps_accounts_linked_and_removes_the_old_replays(tmp_path, copy_demo):
    home = tmp_path / "home"
    catalog = Catalog(copy_demo(home))
    with catalog.session() as orm:
        people = {p.code: p for p in orm.scalars(select(Participant))}
        for code in ("T01", "T03"):
            link_participant(
                orm, create_user(orm, f"trainee-{code}", "correct horse battery", "trainee"), people[code]
            )
        old = orm.scalars(select(Session.uid).where(Session.participant_id == people["T01"].id)).all()
    (home / "replays").mkdir(exist_ok=True)
    for uid in old[:2]:
        (home / "replays" / f"{uid}-vs.mp4").write_bytes(b"video")
    (home / "replays" / "S-not-a-demo-session.mp4").write_bytes(b"kept")

    size = DemoSize(experts=2, expert_sessions=1, trainees=2, practice_sessions=2, retention=False,
                    closures=False, ratings=False)  # fmt: skip
    result = run_demo(catalog, home, size, workers=1)  # in this process: the other pytest worker has a core

    assert result.relinked == ("T01",) and result.unlinked == ("T03",) and result.videos_removed == 2
    with catalog.session() as orm:
        linked = dict(
            orm.execute(
                select(User.username, Participant.code).join(Participant, Participant.user_id == User.id)
            ).all()
        )
        assert linked == {"trainee-T01": "T01"}  # the new T01, in the new study
        assert orm.scalar(select(Participant.study_id).where(Participant.code == "T01")) is not None
    assert sorted(p.name for p in (home / "replays").iterdir()) == ["S-not-a-demo-session.mp4"]
    lines = rerun_lines(result)
    assert lines[0] == "trainee accounts linked again to the new demo's T01"
    assert "T03 are no longer linked" in lines[1] and "removed 2 replay video(s)" in lines[2]
    catalog.close()
