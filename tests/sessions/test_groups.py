"""Groups are a closed, case-insensitive vocabulary (issue 44, seen 4): `participants add T5 --level
Trainee` made a group "Trainee" that no analysis compared, and T5 vanished from every report."""

from __future__ import annotations

import json

from alembic import command
from click.testing import CliRunner
from sqlalchemy import text

from sessions.catalog import Catalog, alembic_config, make_engine
from sessions.catalog.store import CatalogStore
from sessions.cli import main


def _cli(*args):
    return CliRunner().invoke(main, list(args))  # VASCSIM_HOME and the catalog's URL: the home fixture


def test_a_group_typed_in_another_case_is_the_same_group_and_an_unknown_one_is_refused(home):
    """On SQLite and PostgreSQL: "Trainee" is the trainee group; "Traine" is refused in one line that
    lists the groups, and nothing is stored; a study can declare a group of its own."""
    assert _cli("studies", "add", "Course").exit_code == 0
    added = _cli("participants", "add", "T5", "--study", "Course", "--level", "Trainee")
    assert added.exit_code == 0, added.output
    typo = _cli("participants", "add", "T6", "--study", "Course", "--level", "Traine")
    assert typo.exit_code == 1 and typo.output.count("\n") == 1
    listing = "the study's groups are expert, intermediate, trainee, novice"
    remedy = "declare another with `vascsim studies groups Course --add NAME`"  # the CLI's words
    assert f"unknown level 'Traine'; {listing}; {remedy}" in typo.output
    custom = _cli("participants", "add", "F1", "--study", "Course", "--group", "Fellow")
    assert custom.exit_code == 1 and "unknown group 'Fellow'" in custom.output
    declared = _cli("studies", "groups", "Course", "--add", "Fellow")
    assert declared.exit_code == 0 and "declared: fellow" in declared.output
    assert _cli("participants", "add", "F1", "--study", "Course", "--group", "FELLOW").exit_code == 0
    listed = _cli("participants", "list", "--study", "Course", "--json")
    rows = {row["code"]: row for row in json.loads(listed.stdout)}
    assert set(rows) == {"T5", "F1"}  # T6 was never stored
    assert (rows["T5"]["level"], rows["T5"]["group"]) == ("trainee", "trainee")
    assert rows["F1"]["group"] == "fellow"


def test_an_older_catalogs_labels_are_lower_cased_and_unknown_ones_kept_as_declared_groups(tmp_path):
    """The migration keeps every participant in their group: "Trainee" becomes "trainee", and
    "Resident" (outside the standard list) becomes a declared group of its study."""
    url = f"sqlite:///{tmp_path / 'old.sqlite'}"
    engine = make_engine(url)
    with engine.begin() as connection:
        command.upgrade(alembic_config(connection), "0006")
        connection.execute(
            text(
                "INSERT INTO studies (id, name, description, created_at) VALUES (1, 'Old', '', '2026-01-01')"
            )
        )
        for k, (level, group) in enumerate((("Trainee", "Trainee"), ("Resident", ""), ("expert", "EXPERT"))):
            connection.execute(
                text(
                    "INSERT INTO participants (study_id, code, level, handedness, group_label, synthetic, "
                    "created_at) VALUES (1, :code, :level, 'right', :group, 0, '2026-01-01')"
                ),
                {"code": f"P{k}", "level": level, "group": group},
            )
    engine.dispose()
    catalog = Catalog(url)  # upgrades to the newest schema
    people = {p.code: (p.level, p.group) for p in CatalogStore(catalog).participants("Old")}
    assert people == {"P0": ("trainee", "trainee"), "P1": ("resident", ""), "P2": ("expert", "expert")}
    with catalog.session() as orm:
        assert catalog.study(orm, "Old").custom_groups == ["resident"]
    catalog.close()


def test_every_report_accounts_for_every_participant(tmp_path, copy_demo):
    """A participant with no session, one of a group the analysis does not compare: both are named in
    the report with the reason, not silently missing."""
    from metrics.reading.report import write_report
    from sessions.demo import DEMO_STUDY
    from sessions.scoring.analysis import analyse_catalog_study

    catalog = Catalog(copy_demo(tmp_path / "home"))
    store = CatalogStore(catalog)
    store.add_participant(DEMO_STUDY, "T5", "Trainee")
    store.add_participant(DEMO_STUDY, "I1", "intermediate")
    analysis, _ = analyse_catalog_study(catalog, DEMO_STUDY)
    assert {(p["participant"], p["reason"]) for p in analysis.left_out} == {
        ("T5", "no session yet"),
        ("I1", "group 'intermediate' is not one of the two compared (expert, trainee)"),
    }
    page = write_report(analysis, tmp_path / "report").read_text()
    assert 'id="left-out"' in page and "no session yet" in page and "I1" in page
    from fastapi.testclient import TestClient

    from dashboard.app import create_app
    from dashboard.settings import DashboardSettings
    from sessions.catalog.accounts import create_user
    from tests.dashboard.conftest import sign_in

    with catalog.session() as orm:
        create_user(orm, "supervisor", "correct horse battery", "supervisor")
    settings = DashboardSettings(home=tmp_path / "home", database_url=catalog.url)
    with TestClient(create_app(settings, catalog)) as client:
        sign_in(client, "supervisor", "correct horse battery")
        validity = client.get("/studies/1/validity").text
    assert "not counted: " in validity and "T5 (no session yet)" in validity  # the page counts everyone
    catalog.close()
