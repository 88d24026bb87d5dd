"""Verdicts that stay (issue 44, seen 1): a session keeps the verdict it was given and names the
standard version that gave it; a newer version judges only what is recorded after it is set; judging
history again is an explicit act, logged with who, why and how many verdicts changed."""

from __future__ import annotations

import json

from click.testing import CliRunner
from sqlalchemy import select, update

from metrics.study.proficiency import assess_proficiency
from sessions.catalog import Catalog
from sessions.catalog.models import MetricResult, Participant, Session, Verdict
from sessions.cli import main
from sessions.demo import DEMO_STUDY, TASK
from sessions.scoring.analysis import analyse_catalog_study
from sessions.scoring.review import review_session
from sessions.scoring.standards import current_standard


def _cli(home, url, *args):
    env = {"VASCSIM_HOME": str(home), "VASCSIM_DATABASE_URL": url}
    return CliRunner().invoke(main, list(args), env=env)


def _experts_rescored_worse(catalog: Catalog, metrics: list[str]) -> None:
    """More expert data that would move the marks: E01's sessions rescored worse on every mark."""
    with catalog.session() as orm:
        ids = orm.scalars(select(Session.id).join(Participant).where(Participant.code == "E01")).all()
        orm.execute(
            update(MetricResult)
            .where(MetricResult.session_id.in_(ids), MetricResult.metric.in_(metrics))
            .values(value=MetricResult.value * 3 + 1)
        )


def _new_experts_worse(catalog: Catalog, metrics: list[str]) -> None:
    """Two experts recorded after the standard was set (E91, E92), each scoring E01's sessions
    made worse on every mark (x3 + 1), other metrics as E01's."""
    from sessions.catalog import now

    with catalog.session() as orm:
        source = orm.scalar(select(Participant).where(Participant.code == "E01"))
        for code in ("E91", "E92"):
            person = catalog.add_participant(
                orm, source.study, code, level="expert", group_label="expert", synthetic=True
            )
            orm.flush()
            for row in source.sessions:
                copy = Session(
                    uid=f"{row.uid}-{code}",
                    participant_id=person.id,
                    task_id=row.task_id,
                    device=row.device,
                    clock=row.clock,
                    trial=row.trial,
                    phase=row.phase,
                    status=row.status,
                    started_at=now(),
                    ended_at=now(),
                    directory="",
                    error="",
                )
                orm.add(copy)
                orm.flush()
                orm.add_all(
                    MetricResult(
                        session_id=copy.id,
                        metric=m.metric,
                        registry_version=m.registry_version,
                        value=m.value * 3 + 1 if m.metric in metrics and m.value is not None else m.value,
                    )
                    for m in row.metrics
                )


def _study_page(home, url, catalog: Catalog) -> str:
    from fastapi.testclient import TestClient

    from dashboard.app import create_app
    from dashboard.settings import DashboardSettings
    from sessions.catalog.accounts import create_user
    from tests.dashboard.conftest import sign_in

    with catalog.session() as orm:
        create_user(orm, "supervisor", "correct horse battery", "supervisor")
    with TestClient(create_app(DashboardSettings(home=home, database_url=url), catalog)) as client:
        sign_in(client, "supervisor", "correct horse battery")
        return client.get("/studies/1").text


def test_verdicts_stay_under_their_version_until_history_is_rejudged(tmp_path, copy_demo):
    home = tmp_path / "home"
    url = copy_demo(home)
    catalog = Catalog(url)
    first = current_standard(catalog, DEMO_STUDY, TASK)
    before, _ = analyse_catalog_study(catalog, DEMO_STUDY)
    assert set(before.proficiency["standard_version"]) == {1}
    with catalog.session() as orm:  # the demo's own analysis stored every verdict, naming v1
        stored = orm.scalars(select(Verdict)).all()
        assert len(stored) == len(before.sessions)
        assert {v.how for v in stored} == {"recorded before v1 was set; judged under it"}
    marked = [m["metric"] for m in first.marks]
    assert all(len(m["interval"]) == 2 for m in first.marks)  # each mark's interval when set
    _experts_rescored_worse(catalog, marked)
    # today's experts would move every mark beyond its interval: said, with the command, not applied
    moved, _ = analyse_catalog_study(catalog, DEMO_STUDY)
    assert [(e["metric"], e["direction"]) for e in moved.standard_drift] == [
        (m, "more lenient") for m in marked
    ]
    assert moved.proficiency["passed"].equals(before.proficiency["passed"])
    command = f"Consider setting a new version: `vascsim standards set --study {DEMO_STUDY} --task {TASK}`"
    assert any(command in note for note in moved.notes)
    assert 'id="standard-drift"' in _study_page(home, url, catalog)
    assert _cli(home, url, "standards", "set", "--study", DEMO_STUDY, "--task", TASK).exit_code == 0
    second = current_standard(catalog, DEMO_STUDY, TASK)
    after, _ = analyse_catalog_study(catalog, DEMO_STUDY)
    # the marks moved, but no recorded session's verdict did: each still names v1
    assert after.standard_label == second.label() and after.standard_drift == []
    assert set(after.proficiency["standard_version"]) == {1}
    assert after.proficiency["passed"].equals(before.proficiency["passed"])
    assert after.trainees["passes"].tolist() == before.trainees["passes"].tolist()
    rejudge = f"vascsim standards rejudge --study {DEMO_STUDY} --task {TASK} --reason ..."
    assert any(rejudge in note for note in after.notes)
    # a trainee's session's page says which version judged it
    trainee = after.sessions.loc[after.sessions["label"] == "trainee", "session_id"].iloc[0]
    assert review_session(catalog, trainee).standard.startswith(f"the study's {first.label()} on {TASK}")
    # what re-judging would change, worked out independently from v2's marks as stored
    would = assess_proficiency(after.sessions, second.benchmarks())["passed"]
    expected = int((would != after.proficiency["passed"]).sum())
    assert expected > 0  # the rescored experts made v2 more lenient: the test can see a change
    assert _cli(home, url, "standards", "rejudge", "--study", DEMO_STUDY, "--task", TASK).exit_code == 2
    blank = _cli(home, url, "standards", "rejudge", "--study", DEMO_STUDY, "--task", TASK, "--reason", " ")
    assert blank.exit_code == 1 and "say why" in blank.output and blank.output.count("\n") == 1
    done = _cli(
        home,
        url,
        "standards",
        "rejudge",
        "--study",
        DEMO_STUDY,
        "--task",
        TASK,
        "--reason",
        "course board: v2 applies to the whole cohort",
        "--by",
        "Dr A",
        "--json",
    )
    assert done.exit_code == 0, done.output
    assert json.loads(done.stdout) == {"version": 2, "sessions": len(after.sessions), "changed": expected}
    rejudged, _ = analyse_catalog_study(catalog, DEMO_STUDY)
    assert set(rejudged.proficiency["standard_version"]) == {2}
    assert rejudged.proficiency["passed"].tolist() == would.tolist()
    assert review_session(catalog, trainee).standard.startswith(f"the study's {second.label()} on {TASK}")
    shown = _cli(home, url, "standards", "show", "--study", DEMO_STUDY).output
    assert f"by Dr A: {len(after.sessions)} sessions, {expected} verdict(s) changed" in shown
    assert "why: course board: v2 applies to the whole cohort" in shown
    catalog.close()


def test_a_session_keeps_its_verdict_when_its_metrics_are_rescored(tmp_path, copy_demo):
    """A verdict given is kept as given: a later change to the session's stored values (a rescore under
    the same registry) does not turn a recorded pass into a fail (the pass is written as stored, the
    values are moved to the wrong side of every mark)."""
    home = tmp_path / "home"
    url = copy_demo(home)
    catalog = Catalog(url)
    before, _ = analyse_catalog_study(catalog, DEMO_STUDY)
    first = current_standard(catalog, DEMO_STUDY, TASK)
    uid = before.sessions["session_id"].iloc[0]
    with catalog.session() as orm:
        sid = orm.scalar(select(Session.id).where(Session.uid == uid))
        for mark in first.marks:  # every benchmarked value moved to the wrong side of its mark
            worse = mark["benchmark"] * (10 if mark["better"] == "lower" else 0.1) + (
                1 if mark["better"] == "lower" else -1
            )
            orm.execute(
                update(MetricResult)
                .where(MetricResult.session_id == sid, MetricResult.metric == mark["metric"])
                .values(value=worse)
            )
        orm.execute(update(Verdict).where(Verdict.session_id == sid).values(passed=True))
    after, _ = analyse_catalog_study(catalog, DEMO_STUDY)
    assert bool(after.proficiency["passed"].iloc[0]) is True  # the stored verdict, not today's values
    catalog.close()


def test_the_version_in_force_is_the_newest_set_before_the_session():
    from datetime import datetime

    from sessions.scoring.standards import StandardRecord
    from sessions.scoring.verdicts import version_in_force

    def version(n: int, day: int) -> StandardRecord:
        return StandardRecord("s", "t", n, "mean", [], [], [], 5, "1", None, "x", datetime(2026, 12, day), "")

    versions = [version(1, 3), version(2, 5), version(3, 9)]
    assert version_in_force(versions, datetime(2026, 12, 1)).version == 1  # history before v1: v1
    assert version_in_force(versions, datetime(2026, 12, 3)).version == 1
    assert version_in_force(versions, datetime(2026, 12, 6)).version == 2
    assert version_in_force(versions, datetime(2026, 12, 9, 1)).version == 3
    assert version_in_force(versions, None).version == 1


def test_marks_set_before_intervals_were_kept_are_drift_checked_too(tmp_path, copy_demo):
    """Issue 44: marks stored before each kept its interval were never checked for drift. Their
    interval is now rebuilt from the expert sessions the standard names: equal to the one the same
    bootstrap stored, and today's experts moving a mark beyond it are reported."""
    from sessions.catalog.models import Standard
    from sessions.scoring.standards import set_time_intervals

    home = tmp_path / "home"
    catalog = Catalog(copy_demo(home))
    stored = current_standard(catalog, DEMO_STUDY, TASK)
    with catalog.session() as orm:  # as a catalog from before marks kept their interval holds it
        row = orm.scalar(select(Standard))
        row.marks = [{k: v for k, v in m.items() if k != "interval"} for m in row.marks]
    old = current_standard(catalog, DEMO_STUDY, TASK)
    assert not any("interval" in m for m in old.marks)
    analysis, _ = analyse_catalog_study(catalog, DEMO_STUDY)
    rebuilt = set_time_intervals(analysis, old)
    assert [m["interval"] for m in rebuilt] == [m["interval"] for m in stored.marks]
    assert analysis.standard_drift == []
    marked = [m["metric"] for m in old.marks]
    _new_experts_worse(catalog, marked)  # newer expert data: the standard's own sessions unchanged
    moved, _ = analyse_catalog_study(catalog, DEMO_STUDY)
    assert [(e["metric"], e["direction"]) for e in moved.standard_drift] == [
        (m, "more lenient") for m in marked
    ]


def _standing(catalog: Catalog) -> tuple[list, dict, list]:
    """(every standard version as set, session uid -> its kept verdict, the re-judging log) without
    the catalog's own ids."""
    from sessions.catalog.models import Rejudgement, Standard

    with catalog.session() as orm:
        standards = [
            (s.task, s.version, s.rule, s.marks, s.experts, s.sessions, s.min_experts, s.registry_version,
             s.analysis_version, s.set_by, s.set_at, s.note)
            for s in orm.scalars(select(Standard).order_by(Standard.task, Standard.version))
        ]  # fmt: skip
        verdicts = {
            uid: (version, passed, judged_at, how)
            for uid, version, passed, judged_at, how in orm.execute(
                select(Session.uid, Standard.version, Verdict.passed, Verdict.judged_at, Verdict.how)
                .join(Verdict, Verdict.session_id == Session.id)
                .join(Standard, Verdict.standard_id == Standard.id)
            )
        }
        logs = [
            (version, r.judged_by, r.judged_at, r.reason, r.sessions, r.changed)
            for r, version in orm.execute(
                select(Rejudgement, Standard.version).join(Standard, Rejudgement.standard_id == Standard.id)
            )
        ]
    return standards, verdicts, logs


def test_standards_verdicts_and_rejudgings_travel_with_a_bundle(tmp_path, copy_demo):
    """Issue 44: a bundle carried no standard, so the study arrived with no marks, no kept verdicts and
    no record of re-judging. Now every version as set, each session's verdict under the version that
    gave it, and the log travel; a bundle whose verdict names a version it does not carry is refused."""
    import hashlib
    import zipfile

    home = tmp_path / "home"
    url = copy_demo(home)
    assert _cli(home, url, "standards", "set", "--study", DEMO_STUDY, "--task", TASK).exit_code == 0
    why = ["--reason", "the board applies v2 to everyone", "--by", "Dr A"]
    assert _cli(home, url, "standards", "rejudge", "--study", DEMO_STUDY, "--task", TASK, *why).exit_code == 0
    catalog = Catalog(url)
    here = _standing(catalog)
    assert len(here[0]) >= 2 and here[1] and len(here[2]) == 1
    bundle = tmp_path / "demo.zip"
    assert _cli(home, url, "export", "--study", DEMO_STUDY, "-o", str(bundle)).exit_code == 0
    elsewhere, elsewhere_url = tmp_path / "elsewhere", f"sqlite:///{tmp_path / 'elsewhere.sqlite'}"
    imported = _cli(elsewhere, elsewhere_url, "import-bundle", str(bundle))
    assert imported.exit_code == 0, imported.output
    other = Catalog(elsewhere_url)
    assert _standing(other) == here
    arrived, _ = analyse_catalog_study(other, DEMO_STUDY)
    assert set(arrived.proficiency["standard_version"]) == {2}  # judged as they were, not afresh
    with zipfile.ZipFile(bundle) as archive:
        manifest = json.loads(archive.read("manifest.json"))
    manifest["study"]["name"] = "forged"
    manifest["sessions"][0]["verdict"]["standard_version"] = 9
    raw = json.dumps(manifest).encode()
    forged = tmp_path / "forged.zip"
    with zipfile.ZipFile(bundle) as source, zipfile.ZipFile(forged, "w") as target:
        for info in source.infolist():
            data = source.read(info.filename)
            if info.filename == "manifest.json":
                data = raw
            elif info.filename == "manifest.sha256":
                data = hashlib.sha256(raw).hexdigest().encode()
            target.writestr(info.filename, data)
    refused = _cli(tmp_path / "third", f"sqlite:///{tmp_path / 'third.sqlite'}", "import-bundle", str(forged))
    assert refused.exit_code == 1 and "names standard v9" in refused.output, refused.output
    assert refused.output.count("\n") == 1
    catalog.close()
    other.close()


def test_a_study_of_experts_alone_says_which_group_has_no_session_in_plain_words(tmp_path):
    """Seen: with only experts scored, the verdict read "group(s) 'trainee' not found in column
    'label' (it holds 'expert')", the analysis's own words."""
    from sessions.running.runner import SessionPlan, run_session
    from sessions.synthetic import pass_parameters

    catalog = Catalog(f"sqlite:///{tmp_path / 'catalog.sqlite'}")
    with catalog.session() as orm:
        study = catalog.study(orm, "S", create=True)
        catalog.add_participant(orm, study, "E1", level="expert")
    plan = SessionPlan("S", "E1", "wall-stitch", None)
    uid = run_session(catalog, tmp_path, plan, pass_parameters(0.95, 1))
    review = review_session(catalog, uid)
    assert review.verdict == "no standard"
    assert review.standard == (
        "no standard for wall-stitch in this study yet: a standard compares two groups, and no "
        "participant in group 'trainee' has a scored session of it"
    )
