"""A participant's progress as the dashboard serves it (issue 25): learning curves in the units a surgeon
reads, each point coloured by its own session's pass (seen: colours taken by position from a list
that holds every task's sessions), and the trainee's feedback from the same analysis as the report."""

from __future__ import annotations

import numpy as np
import pytest
from fastapi.testclient import TestClient
from sqlalchemy import select

from dashboard.app import create_app
from dashboard.settings import DashboardSettings
from metrics.reading.feedback import participant_feedback
from sessions.catalog.accounts import create_user
from sessions.catalog.models import Participant
from sessions.demo import DEMO_STUDY
from sessions.scoring.analysis import analyse_catalog_study
from tests.dashboard.conftest import sign_in


@pytest.fixture(scope="module")
def served(demo_catalog):
    """(participant T01's progress, the study's validity report) as the API serves them."""
    catalog, home = demo_catalog
    with catalog.session() as orm:
        create_user(orm, "curves-supervisor", "correct horse battery", "supervisor")
        trainee, study = orm.execute(
            select(Participant.id, Participant.study_id).where(Participant.code == "T01")
        ).one()
    app = create_app(DashboardSettings(home=home, database_url=catalog.url), catalog)
    with TestClient(app) as client:
        sign_in(client, "curves-supervisor", "correct horse battery")
        yield (
            client.get(f"/api/participants/{trainee}/progress").json(),
            client.get(f"/api/studies/{study}/validity").json(),
        )


@pytest.fixture(scope="module")
def progress(served):
    return served[0]


def test_the_validity_tables_medians_are_in_display_units(served, demo_catalog):
    """Seen: the validity page's medians in SI (entry_to_target 0.000137 m) beside mm everywhere else."""
    catalog, _ = demo_catalog
    analysis, _ = analyse_catalog_study(catalog, DEMO_STUDY)
    si = analysis.validity.table.set_index("metric")
    shown = {row["metric"]: row for row in served[1]["table"]}
    assert shown["entry_to_target"]["unit"] == "mm"
    assert shown["entry_to_target"]["median_expert"] == pytest.approx(
        1e3 * si.at["entry_to_target", "median_expert"]
    )
    assert shown["tip_speed_after_pierce"]["unit"] == "mm/s"


def test_learning_curves_are_in_display_units_with_each_points_own_pass(progress, demo_catalog):
    catalog, _ = demo_catalog
    analysis, _ = analyse_catalog_study(catalog, DEMO_STUDY)
    rows = analysis.sessions[analysis.sessions["participant_id"] == "T01"]
    curves = {c["metric"]: c for c in progress["curves"]}
    speed = curves["tip_speed_before_pierce"]
    assert speed["unit"] == "mm/s"
    np.testing.assert_allclose(speed["value"], 1e3 * rows["tip_speed_before_pierce"].to_numpy(), rtol=1e-12)
    bench = analysis.benchmarks.set_index("metric").loc["tip_speed_before_pierce", "benchmark"]
    assert speed["benchmark"] == pytest.approx(1e3 * bench)
    assert curves["entry_angle_error_deg"]["unit"] == "deg"
    assert speed["passed"] == [bool(p) for p in analysis.proficiency.loc[rows.index, "passed"]]
    assert len(speed["passed"]) == len(speed["trial"]) == len(rows)


def test_the_participant_page_carries_the_reports_feedback(progress, demo_catalog):
    catalog, _ = demo_catalog
    analysis, _ = analyse_catalog_study(catalog, DEMO_STUDY)
    expected = participant_feedback(analysis, "T01")
    assert progress["feedback"]["work_on"] == expected["work_on"]
    assert progress["feedback"]["strengths"] == expected["strengths"]
    assert progress["feedback"]["trials"] == expected["trials"] and len(expected["trials"]) == 3
