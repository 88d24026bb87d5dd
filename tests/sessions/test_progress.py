"""Each participant's progress and status as CSV or an Excel workbook: the same table from the CLI
and the dashboard, with units and direction in its headers, and the status said in words."""

from __future__ import annotations

import io

import pandas as pd
import pytest
from click.testing import CliRunner
from fastapi.testclient import TestClient
from sqlalchemy import select

from dashboard.app import create_app
from dashboard.settings import DashboardSettings
from sessions.catalog.accounts import create_user, link_participant
from sessions.catalog.models import Participant, Study
from sessions.cli import main
from sessions.demo import DEMO_STUDY
from sessions.exchange.progress import progress_table
from sessions.scoring.analysis import analyse_catalog_study
from tests.dashboard.conftest import sign_in

PASSWORD = "correct horse battery"


def test_the_progress_table_reads_as_the_analysis_says(demo_catalog):
    catalog, _ = demo_catalog
    table = progress_table(catalog, DEMO_STUDY).set_index("participant")
    analysis, _ = analyse_catalog_study(catalog, DEMO_STUDY)
    assert list(table.index) == ["E01", "E02", "T01", "T02", "T03"]
    assert (table.loc[["E01", "E02"], "status"] == "sets the benchmark").all()
    for row in analysis.trainees.itertuples():
        status = table.at[row.participant_id, "status"]
        if row.proficient:
            assert status.startswith(f"proficient at trial {int(row.trials_to_proficiency)}")
        else:
            assert status.startswith(f"not yet proficient after {row.practice_sessions} practice sessions")
        assert ("retention held" in status) == bool(row.retention_passed)
    header = "entry_angle_error_deg, latest (deg, lower is better)"
    mine = analysis.sessions[analysis.sessions["participant_id"] == "T02"]
    assert table.at["T02", header] == pytest.approx(float(mine["entry_angle_error_deg"].iloc[-1]))
    speed = "tip_speed_before_pierce, benchmark (mm/s, lower is better)"  # SI m/s stored, mm/s shown
    bench = analysis.benchmarks.set_index("metric").at["tip_speed_before_pierce", "benchmark"]
    assert table.at["T01", speed] == pytest.approx(1e3 * bench)
    assert (
        table.loc["T01", "sessions passed"]
        == analysis.proficiency.loc[analysis.sessions["participant_id"] == "T01", "passed"].sum()
    )


def test_cli_exports_xlsx_and_csv_with_the_same_rows(demo_catalog, tmp_path, monkeypatch):
    catalog, home = demo_catalog
    monkeypatch.setenv("VASCSIM_HOME", str(home))
    monkeypatch.setenv("VASCSIM_DATABASE_URL", catalog.url)
    runner = CliRunner()
    book, text = tmp_path / "progress.xlsx", tmp_path / "progress.csv"
    for path in (book, text):
        done = runner.invoke(main, ["participants", "export", "--study", DEMO_STUDY, "-o", str(path)])
        assert done.exit_code == 0 and done.stdout == f"wrote {path} (5 participants)\n"
    sheet = pd.read_excel(book, sheet_name=DEMO_STUDY)
    plain = pd.read_csv(text)
    expected = progress_table(catalog, DEMO_STUDY)
    assert list(sheet.columns) == list(plain.columns) == list(expected.columns)
    assert list(sheet["status"]) == list(plain["status"]) == list(expected["status"])
    column = "entry_angle_error_deg, latest (deg, lower is better)"
    assert sheet[column].to_numpy() == pytest.approx(expected[column].to_numpy(), rel=1e-3)
    bad = runner.invoke(
        main, ["participants", "export", "--study", DEMO_STUDY, "-o", str(tmp_path / "p.ods")]
    )
    assert (
        bad.exit_code == 1
        and bad.output == f"vascsim: error: progress file {tmp_path / 'p.ods'}: use .csv or .xlsx\n"
    )


def test_the_dashboard_serves_the_same_table_to_staff_only(demo_catalog):
    catalog, home = demo_catalog
    with catalog.session() as orm:
        study = orm.scalar(select(Study).where(Study.name == DEMO_STUDY))
        create_user(orm, "supervisor", PASSWORD, "supervisor")
        trainee = create_user(orm, "trainee", PASSWORD, "trainee")
        link_participant(orm, trainee, orm.scalar(select(Participant).where(Participant.code == "T01")))
        study_id = study.id
    app = create_app(DashboardSettings(home=home, database_url=catalog.url), catalog)
    with TestClient(app) as client:
        sign_in(client, "supervisor", PASSWORD)
        page = client.get(f"/studies/{study_id}").text
        assert f"/api/studies/{study_id}/progress.xlsx" in page
        answer = client.get(f"/api/studies/{study_id}/progress.xlsx")
        assert (
            answer.status_code == 200
            and 'filename="progress-synthetic-demo.xlsx"' in answer.headers["content-disposition"]
        )
        served = pd.read_excel(io.BytesIO(answer.content))
        assert list(served["status"]) == list(progress_table(catalog, DEMO_STUDY)["status"])
        assert client.get(f"/api/studies/{study_id}/progress.ods").status_code == 404
        # the validity table as downloaded: medians in display units, the headers saying so
        csv = pd.read_csv(io.StringIO(client.get(f"/api/studies/{study_id}/validity.csv").text))
        assert "median expert (participant medians, in unit)" in csv.columns
        analysis, _ = analyse_catalog_study(catalog, DEMO_STUDY)
        si = analysis.validity.table.set_index("metric")
        row = csv.set_index("metric").loc["entry_to_target"]
        assert row["unit (of the medians)"] == "mm"
        assert row["median expert (participant medians, in unit)"] == pytest.approx(
            1e3 * si.at["entry_to_target", "median_expert"]
        )
    with TestClient(app) as client:
        sign_in(client, "trainee", PASSWORD)
        assert client.get(f"/api/studies/{study_id}/progress.csv").status_code == 403
