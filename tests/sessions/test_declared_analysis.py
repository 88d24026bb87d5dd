"""One analysis per study (issue 20, seen 2): declared once in the catalog, versioned, and the same
benchmarks and pass/fail from `vascsim report`, the JSON API and the dashboard pages."""

from __future__ import annotations

import dataclasses
import json
import re

import pytest
from click.testing import CliRunner
from fastapi.testclient import TestClient
from sqlalchemy import delete, func, select

from dashboard.app import create_app
from dashboard.settings import DashboardSettings
from sessions.catalog import Catalog, CatalogError
from sessions.catalog.accounts import create_user
from sessions.catalog.models import Participant, Session, Study
from sessions.cli import main
from sessions.demo import DEMO_ANALYSIS, DEMO_STUDY
from sessions.scoring.analysis import (
    analyse_catalog_study,
    analysis_history,
    declare_analysis,
    declared_settings,
    settings_from_json,
)
from tests.conftest import REDUCED_DEMO_SIZE
from tests.dashboard.conftest import sign_in

PASSWORD = "correct horse battery"
PARTICIPANTS = REDUCED_DEMO_SIZE["experts"] + REDUCED_DEMO_SIZE["trainees"]


@pytest.fixture(scope="module")
def demo(tmp_path_factory, copy_demo):
    home = tmp_path_factory.mktemp("home")
    catalog = Catalog(copy_demo(home))
    with catalog.session() as orm:
        create_user(orm, "supervisor", PASSWORD, "supervisor")
    yield catalog, home
    catalog.close()


def _cli(home, *args):
    env = {"VASCSIM_HOME": str(home), "VASCSIM_DATABASE_URL": f"sqlite:///{home / 'catalog.sqlite'}"}
    result = CliRunner().invoke(main, list(args), env=env)
    assert result.exit_code == 0, result.output
    return result


def test_the_demo_declares_its_analysis(demo):
    catalog, _ = demo
    settings, version, author = declared_settings(catalog, DEMO_STUDY)
    fixture = dataclasses.replace(DEMO_ANALYSIS, benchmark_override=REDUCED_DEMO_SIZE["benchmark_override"])
    assert DEMO_ANALYSIS.benchmark_metrics == tuple(
        m for m in DEMO_ANALYSIS.metrics if m != "spectral_arc_length"
    )
    assert DEMO_ANALYSIS.baseline_trials == 2 and DEMO_ANALYSIS.benchmark_rule == "mean+sd:2"
    assert version == 1 and author == "vascsim demo" and settings == fixture


def test_the_demo_rates_every_session_with_two_synthetic_raters_and_reports_every_strand(demo):
    """Two synthetic raters (named so) score every demo session with the GRS; the analysis every
    front-end uses then carries inter-rater agreement, concurrent validity against the GRS total,
    test-retest and standard setting."""
    from sessions.catalog.models import Rating
    from sessions.scoring.ratings import study_ratings

    catalog, _ = demo
    ratings = study_ratings(catalog, DEMO_STUDY)
    totals = ratings[ratings["item"] == "total"]
    with catalog.session() as orm:
        sessions = orm.scalar(select(func.count(Session.id)))
        assert orm.scalar(select(func.count(Rating.id))) == sessions * 2 * 7  # six items and the total
    assert set(totals["rater"]) == {"synthetic rater A", "synthetic rater B"}
    assert totals.groupby("session_id")["rater"].nunique().eq(2).all() and len(totals) == 2 * sessions
    analysis, _ = analyse_catalog_study(catalog, DEMO_STUDY)
    agreement = analysis.reliability.raters["GRS"].set_index("item")
    assert agreement.loc["total", "block_raters"] == 2 and agreement.loc["total", "icc21"] > 0.5
    assert analysis.concurrent is not None and analysis.concurrent.rating_col == "grs_total"
    assert set(analysis.standards.misclassification["rule"]) >= {"contrasting", "mean+sd:2"}
    assert len(analysis.standards.leave_one_expert_out) == REDUCED_DEMO_SIZE["experts"]  # a row per expert
    assert analysis.reliability.test_retest["participants"].max() == PARTICIPANTS


def test_cli_report_api_and_pages_agree_on_benchmarks_and_every_pass(demo):
    """Seen: `vascsim report` (rule mean, all metrics) and the dashboard (percentile 75) differed."""
    catalog, home = demo
    report = json.loads(_cli(home, "report", "--study", DEMO_STUDY, "--json").stdout)
    assert report["analysis_version"] == 1 and report["overridden"] == {}
    cli_benchmarks = {b["metric"]: (b["benchmark"], b["rule"]) for b in report["benchmarks"]}
    assert {rule for _, rule in cli_benchmarks.values()} == {DEMO_ANALYSIS.benchmark_rule}
    cli_passed = {row["session_id"]: row["passed"] for row in report["proficiency"]}

    app = create_app(DashboardSettings(home=home, database_url=catalog.url), catalog)
    with TestClient(app) as client:
        sign_in(client, "supervisor", PASSWORD)
        with catalog.session() as orm:
            study_id = orm.scalar(select(Study.id).where(Study.name == DEMO_STUDY))
            people = orm.execute(
                select(Participant.id, Participant.code).where(Participant.study_id == study_id)
            ).all()
        overview = client.get(f"/api/studies/{study_id}").json()
        api_benchmarks = {b["metric"]: (b["benchmark"], b["rule"]) for b in overview["benchmarks"]}
        assert api_benchmarks == cli_benchmarks
        api_passed = {}
        for participant_id, _ in people:
            progress = client.get(f"/api/participants/{participant_id}/progress").json()
            api_passed.update({s["uid"]: s["passed"] for s in progress["sessions"]})
            assert {
                b["metric"]: (b["benchmark"], b["rule"]) for b in progress["benchmarks"]
            } == cli_benchmarks
        assert api_passed == cli_passed
        page = client.get(f"/studies/{study_id}").text
        table = page[page.index('id="benchmarks"') : page.index("</table>", page.index('id="benchmarks"'))]
        shown = re.findall(r"<tr><td title=\"(\w+)\">[^<]+</td><td class=\"num\">([^<]+)</td>", table)
        assert shown == [
            (b["metric"], b["pass_if"].replace(">", "&gt;").replace("<", "&lt;"))
            for b in report["benchmarks"]
        ]
        # standard setting and inter-rater agreement: the same numbers in the CLI and the dashboard
        validity = client.get(f"/api/studies/{study_id}/validity").json()
        marks = validity["standards"]["tables"]["marks"]
        cli_marks = report["standard_setting"]
        assert len(marks["rows"]) == len(cli_marks) > 0
        column = marks["columns"].index("false fail (experts)")
        for row, cli in zip(marks["rows"], cli_marks, strict=True):
            assert row[column] == cli["false_fail_shown"]
        total = next(r for r in report["inter_rater"]["GRS"] if r["item"] == "total")
        shown_total = validity["reliability"]["raters"][0]["table"]["rows"][-1]
        assert shown_total[0] == "total" and shown_total[3].startswith(f"{total['icc21']:.2f}")
        page = client.get(f"/studies/{study_id}/validity").text
        assert 'id="standard-setting"' in page and "Inter-rater agreement: GRS" in page


def test_an_override_is_for_one_run_and_is_named(demo):
    catalog, home = demo
    result = _cli(home, "report", "--study", DEMO_STUDY, "--rule", "mean", "--json")
    data = json.loads(result.stdout)
    assert data["overridden"] == {"benchmark_rule": {"declared": "mean+sd:2", "used": "mean"}}
    assert {b["rule"] for b in data["benchmarks"]} == {"mean"}
    analysis, source = analyse_catalog_study(catalog, DEMO_STUDY, {"benchmark_rule": "mean"})
    assert any("Overridden for this run only: benchmark_rule mean+sd:2 -> mean" in n for n in analysis.notes)
    assert declared_settings(catalog, DEMO_STUDY)[1] == 1  # the declaration itself is unchanged


def test_declarations_are_versioned_never_edited(tmp_path):
    catalog = Catalog(f"sqlite:///{tmp_path / 'c.sqlite'}")
    with catalog.session() as orm:
        catalog.study(orm, "course", create=True)
    first = dataclasses.replace(DEMO_ANALYSIS, benchmark_rule="median")
    assert declare_analysis(catalog, "course", first, "alice", "initial") == 1
    assert declare_analysis(catalog, "course", first, "bob") == 1  # nothing changed: no new version
    assert declare_analysis(catalog, "course", DEMO_ANALYSIS, "bob", "as the demo") == 2
    history = analysis_history(catalog, "course")
    assert [(h["version"], h["author"], h["settings"]["benchmark_rule"]) for h in history] == [
        (1, "alice", "median"),
        (2, "bob", "mean+sd:2"),
    ]
    catalog.close()


@pytest.mark.parametrize(
    "data, message",
    [
        ({"rule": "mean"}, "unknown analysis setting.*rule"),
        ({"groups": "expert"}, "groups must be a list of names"),
        ({"groups": ["expert", "expert"]}, "two different groups"),
        ({"metrics": ["no_such_metric"]}, "unknown metric 'no_such_metric'"),
        ({"consecutive_passes": 0}, "consecutive_passes must be a whole number"),
        ({"consecutive_passes": True}, "consecutive_passes must be a whole number"),
        ({"retention_baseline": 0}, "retention_baseline must be a whole number"),
        ({"alpha": float("nan")}, "alpha must be a number between 0 and 1"),
        ({"benchmark_rule": "percentile:0"}, "percentile rule"),
        ({"level": "cohort"}, "level must be"),
        ([], "must be an object"),
    ],
)
def test_a_bad_declaration_names_its_field(data, message):
    with pytest.raises(CatalogError, match=f"^declaration: .*{message}"):
        settings_from_json(data, "declaration")


def test_cli_declares_and_shows(demo):
    _, home = demo
    shown = _cli(home, "studies", "analysis", DEMO_STUDY).stdout
    assert "declared analysis version 1" in shown and "mean+sd:2" in shown


def test_what_counts_as_retention_is_declared_and_used(tmp_path, copy_demo):
    catalog = Catalog(copy_demo(tmp_path))
    before, _ = analyse_catalog_study(catalog, DEMO_STUDY)
    _cli(
        tmp_path,
        "studies",
        "analysis",
        DEMO_STUDY,
        "--retention-baseline",
        "1",
        "--note",
        "last session only",
    )
    after, source = analyse_catalog_study(catalog, DEMO_STUDY)
    assert source.version == 2 and after.settings.retention_baseline == 1
    column = next(c for c in before.trainees.columns if c.startswith("retention_change_"))
    sessions = after.sessions
    for row in after.trainees.itertuples():
        mine = sessions[
            (sessions["participant_id"] == row.participant_id) & (sessions["phase"] == "practice")
        ]
        delayed = sessions[
            (sessions["participant_id"] == row.participant_id) & (sessions["phase"] == "retention")
        ]
        metric = column[len("retention_change_") :]
        expected = float(delayed[metric].iloc[-1]) - float(mine[metric].iloc[-1])
        assert getattr(row, column) == pytest.approx(expected)
    assert any("mean of their last 1 practice sessions" in line for line in _method(after))
    catalog.close()


def _method(analysis):
    from metrics.reading.report import method_lines

    return method_lines(analysis)


def test_results_of_an_older_registry_are_stale_until_rescored(tmp_path, copy_demo):
    """A registry version bump: old results are shown as stale, left out with a note, and rescored."""
    from sqlalchemy import update

    from metrics.session.registry import REGISTRY_VERSION
    from sessions.catalog.models import MetricResult, Session

    home = tmp_path
    catalog = Catalog(copy_demo(home))
    with catalog.session() as orm:
        old = orm.scalar(select(Session).order_by(Session.id).limit(1))
        uid = old.uid
        orm.execute(
            update(MetricResult).where(MetricResult.session_id == old.id).values(registry_version="2")
        )
    listed = json.loads(_cli(home, "sessions", "list", "--json").stdout)
    assert {r["session"]: r["metrics"] for r in listed}[uid] == "stale (v2)"
    assert sum(r["metrics"] == "current" for r in listed) == len(listed) - 1
    text = _cli(home, "sessions", "list").stdout
    assert f"rescore: vascsim score --study {DEMO_STUDY}" in text
    analysis, _ = analyse_catalog_study(catalog, DEMO_STUDY)
    assert any("older registry version" in note and uid in note for note in analysis.notes)
    _cli(home, "score", "--study", DEMO_STUDY)
    listed = json.loads(_cli(home, "sessions", "list", "--json").stdout)
    assert all(r["metrics"] == "current" for r in listed), listed
    assert REGISTRY_VERSION == "10"
    catalog.close()


def test_concurrent_validity_from_catalogued_ratings(demo):
    """GRS totals stored as ratings become a column of the study table, and a report against them."""
    from datetime import datetime

    from sessions.catalog.models import Rating, Session
    from sessions.catalog.store import CatalogStore

    catalog, home = demo
    with catalog.session() as orm:
        orm.execute(delete(Rating))  # the demo's synthetic raters: this test rates on its own
        rows = orm.execute(
            select(Session.id, Participant.group_label)
            .join(Participant, Session.participant_id == Participant.id)
            .join(Study, Participant.study_id == Study.id)
            .where(Study.name == DEMO_STUDY)
        ).all()
        for k, (session_id, group) in enumerate(rows):
            for rater, offset in (("A", 0.0), ("B", 1.0)):
                score = (24.0 if group == "expert" else 12.0) + (k % 3) + offset
                orm.add(
                    Rating(
                        session_id=session_id, rater=rater, instrument="GRS", item="total", score=score,
                        created_at=datetime(2026, 12, 2),
                    )
                )  # fmt: skip
    table = CatalogStore(catalog).study_table(DEMO_STUDY)
    assert table["grs_total"].notna().all() and table["grs_total"].min() >= 12.5  # mean of the two raters
    data = json.loads(_cli(home, "report", "--study", DEMO_STUDY, "--rating", "grs_total", "--json").stdout)
    assert data["overridden"] == {"rating_col": {"declared": None, "used": "grs_total"}}
    concurrent = {row["metric"]: row for row in data["concurrent"]}
    assert set(concurrent) == set(DEMO_ANALYSIS.metrics)
    assert all(row["n"] == PARTICIPANTS for row in concurrent.values())  # participants, not sessions
    assert all(
        row["rho_ci_low"] is None or row["rho_ci_low"] != row["rho_ci_low"] for row in concurrent.values()
    )


def test_an_analysis_is_declared_on_a_study_before_its_data(tmp_path):
    """Issue 44, seen 3: pre-registration. A new course with no session yet declares its analysis;
    the shown defaults say what each means (not "every metric with values" for a task or a rating);
    a command suggested in a message quotes the study's name so it pastes as shown."""
    study = "Vascular Course Nov 2026"
    _cli(tmp_path, "studies", "add", study)
    env = {"VASCSIM_HOME": str(tmp_path), "VASCSIM_DATABASE_URL": f"sqlite:///{tmp_path / 'catalog.sqlite'}"}
    defaults = _cli(tmp_path, "studies", "analysis", study).stdout
    assert "no analysis declared" in defaults
    lines = {line.split()[0]: line for line in defaults.splitlines()[1:]}
    assert "the study's only task" in lines["task"] and "GRS or OSATS" in lines["rating_col"]
    assert "primary metrics" in lines["metrics"] and "every metric" not in defaults
    declared = _cli(tmp_path, "studies", "analysis", study, "--metrics", "task_time,entry_to_target")
    assert f"study {study!r}: analysis version 1 declared" in declared.stdout
    assert "task_time, entry_to_target" in declared.stdout
    report = CliRunner().invoke(main, ["report", "--study", study], env=env)
    assert report.exit_code == 1
    assert "run `vascsim score --study 'Vascular Course Nov 2026'` first" in report.output


def test_left_at_its_default_an_analysis_uses_the_tasks_primary_metrics(tmp_path, copy_demo):
    """Not all 38: the analysed task's declared primary metrics, and the analysis says so."""
    from sessions.tasks import task_spec

    catalog = Catalog(copy_demo(tmp_path))
    declare_analysis(
        catalog, DEMO_STUDY, dataclasses.replace(DEMO_ANALYSIS, metrics=None), "supervisor", "the default"
    )
    analysis, _ = analyse_catalog_study(catalog, DEMO_STUDY)
    primaries = task_spec(DEMO_ANALYSIS.task).primary_metrics
    assert analysis.validity.table["metric"].tolist() == list(primaries)
    assert any(n.startswith(f"Metrics: the task's {len(primaries)} primary metrics") for n in analysis.notes)
    catalog.close()
