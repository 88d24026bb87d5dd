"""Standards that stand still (issue 44, seen 1): adding sessions changed the demo's benchmarks from
four metrics to two and flipped passes of people who had done nothing. A standard is now set once,
stored with where it came from, versioned, and judged against as stored."""

from __future__ import annotations

import json

from click.testing import CliRunner
from sqlalchemy import select, update

from metrics.reading.report import write_report
from sessions.catalog import Catalog
from sessions.catalog.models import MetricResult, Participant, Session
from sessions.cli import main
from sessions.demo import DEMO_STUDY, TASK
from sessions.scoring.analysis import analyse_catalog_study
from sessions.scoring.standards import current_standard


def _cli(home, url, *args):
    env = {"VASCSIM_HOME": str(home), "VASCSIM_DATABASE_URL": url}
    return CliRunner().invoke(main, list(args), env=env)


def test_marks_stand_still_when_sessions_change_until_a_new_version_is_set(tmp_path, copy_demo):
    home = tmp_path / "home"
    url = copy_demo(home)
    catalog = Catalog(url)
    first = current_standard(catalog, DEMO_STUDY, TASK)
    assert first is not None and first.version == 1 and first.set_by == "vascsim demo"
    assert first.experts == ["E01", "E02"] and len(first.sessions) == 4 and first.provisional
    before, _ = analyse_catalog_study(catalog, DEMO_STUDY)
    assert before.standard_label == first.label()
    # more expert data arrives (here: E01's sessions rescored worse on every benchmarked metric)
    marked = [m["metric"] for m in first.marks]
    with catalog.session() as orm:
        ids = orm.scalars(select(Session.id).join(Participant).where(Participant.code == "E01")).all()
        orm.execute(
            update(MetricResult)
            .where(MetricResult.session_id.in_(ids), MetricResult.metric.in_(marked))
            .values(value=MetricResult.value * 3 + 1)
        )
    after, _ = analyse_catalog_study(catalog, DEMO_STUDY)
    assert after.benchmarks[["metric", "benchmark"]].equals(before.benchmarks[["metric", "benchmark"]])
    trainees = after.sessions["label"] == "trainee"
    assert after.proficiency.loc[trainees, "passed"].equals(before.proficiency.loc[trainees, "passed"])
    candidate, _ = analyse_catalog_study(catalog, DEMO_STUDY, standard="candidate")
    assert not candidate.benchmarks["benchmark"].equals(before.benchmarks["benchmark"])  # they would move
    # a new version is explicit, and from then on it is the one judged against
    made = _cli(
        home, url, "standards", "set", "--study", DEMO_STUDY, "--task", TASK, "--note", "E01 rescored"
    )
    assert made.exit_code == 0, made.output
    assert made.output.startswith(f"study {DEMO_STUDY!r}, {TASK}: standard v2, set ")
    newer, _ = analyse_catalog_study(catalog, DEMO_STUDY)
    assert newer.standard_label.startswith("standard v2")
    shown = json.loads(_cli(home, url, "standards", "show", "--study", DEMO_STUDY, "--json").stdout)
    assert [s["version"] for s in shown] == [1, 2] and shown[1]["note"] == "E01 rescored"
    page = write_report(newer, tmp_path / "report").read_text()
    assert f"Proficiency benchmarks: {newer.standard_label}" in page
    catalog.close()


def test_the_study_page_names_the_standard_in_force_and_follows_a_new_version(tmp_path, copy_demo):
    """The dashboard's cached analysis is keyed on the standards too: a version set on the command
    line is the one the page names at the next request."""
    from fastapi.testclient import TestClient

    from dashboard.app import create_app
    from dashboard.settings import DashboardSettings
    from sessions.catalog.accounts import create_user
    from tests.dashboard.conftest import sign_in

    home = tmp_path / "home"
    url = copy_demo(home)
    catalog = Catalog(url)
    with catalog.session() as orm:
        create_user(orm, "supervisor", "correct horse battery", "supervisor")
    app = create_app(DashboardSettings(home=home, database_url=url), catalog)
    with catalog.session() as orm:
        create_user(orm, "researcher", "correct horse battery", "researcher")
    with TestClient(app) as client:
        csrf = sign_in(client, "supervisor", "correct horse battery")
        assert "Proficiency benchmarks: standard v1, set " in client.get("/studies/1").text
        assert _cli(home, url, "standards", "set", "--study", DEMO_STUDY, "--task", TASK).exit_code == 0
        assert "Proficiency benchmarks: standard v2, set " in client.get("/studies/1").text
        # the supervisor's action on the page: a third version, signed with their name
        form = {"csrf_token": csrf, "task": TASK, "note": "two more experts recorded"}
        made = client.post("/studies/1/standards", data=form, follow_redirects=False)
        assert made.status_code == 303 and made.headers["location"] == "/studies/1?standard=3"
        page = client.get(made.headers["location"]).text
        assert "Standard v3 set." in page and "Proficiency benchmarks: standard v3, set " in page
        third = current_standard(catalog, DEMO_STUDY, TASK)
        assert (third.set_by, third.note) == ("supervisor", "two more experts recorded")
        refused = client.post("/studies/1/standards", data={**form, "task": "no-such-task"})
        assert refused.status_code >= 400 and 'id="standard-error"' in refused.text
        assert current_standard(catalog, DEMO_STUDY, TASK).version == 3
    with TestClient(app) as other:
        csrf = sign_in(other, "researcher", "correct horse battery")
        assert 'id="set-standard"' not in other.get("/studies/1").text
        denied = other.post("/studies/1/standards", data={"csrf_token": csrf, "task": TASK})
        assert denied.status_code == 403 and current_standard(catalog, DEMO_STUDY, TASK).version == 3
    catalog.close()


def test_no_standard_can_be_set_where_no_metric_qualifies(tmp_path, copy_demo):
    """Declared without the fixture's override reason, two experts and three trainees give no AUC
    interval: setting a standard is refused in one line that says why, and nothing is stored."""
    home = tmp_path / "home"
    url = copy_demo(home)
    undone = _cli(
        home, url, "studies", "analysis", DEMO_STUDY, "--override-reason", "", "--note", "no reason"
    )
    assert undone.exit_code == 0, undone.output
    refused = _cli(home, url, "standards", "set", "--study", DEMO_STUDY, "--task", TASK)
    assert refused.exit_code == 1 and refused.output.count("\n") == 1
    assert f"no standard can be set for {TASK} in study {DEMO_STUDY!r}: No standard:" in refused.output
    shown = json.loads(_cli(home, url, "standards", "show", "--study", DEMO_STUDY, "--json").stdout)
    assert [s["version"] for s in shown] == [1]  # the demo's own, unchanged
