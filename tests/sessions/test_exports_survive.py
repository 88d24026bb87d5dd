"""Exports survive real data (issue 44, item 9): a study where some sessions never pierced (their
placement metrics are missing), failed, were never scored or were recovered still gives its xAPI
statements, progress table (CSV and XLSX), bundle and report, with no traceback.

Each example is a copy of the reduced demo changed at random in those ways."""

from __future__ import annotations

import json
import math
import tempfile
from pathlib import Path

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from sqlalchemy import delete, select, update

from sessions.catalog import Catalog
from sessions.catalog.models import MetricResult, Session
from sessions.demo import DEMO_STUDY
from sessions.status import SessionStatus

PLACEMENT = ("entry_angle_deg", "entry_to_target", "bite_depth", "peak_force", "tip_speed_after_pierce")
"""Metrics a session that never pierced has no value for."""

CHANGES = st.sampled_from(["as recorded", "never pierced", "all missing", "failed", "unscored", "recovered"])


def change_sessions(catalog: Catalog, changes: list[str]) -> int:
    """Apply ``changes`` to the study's sessions in trial order (the rest stay as recorded); the
    number of sessions."""
    with catalog.session() as orm:
        sessions = list(orm.scalars(select(Session).order_by(Session.participant_id, Session.trial)))
        for session, change in zip(sessions, changes, strict=False):
            if change == "never pierced":
                orm.execute(
                    update(MetricResult)
                    .where(MetricResult.session_id == session.id, MetricResult.metric.in_(PLACEMENT))
                    .values(value=None)
                )
            elif change == "all missing":
                orm.execute(
                    update(MetricResult).where(MetricResult.session_id == session.id).values(value=None)
                )
            elif change == "failed":
                session.status = SessionStatus.FAILED.value
                session.error = "the simulation stopped (injected)"
            elif change == "unscored":
                orm.execute(delete(MetricResult).where(MetricResult.session_id == session.id))
            elif change == "recovered":
                session.status = SessionStatus.RECOVERED.value
        orm.commit()
    return len(sessions)


@settings(max_examples=4, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(changes=st.lists(CHANGES, min_size=4, max_size=16))
def test_exports_of_a_study_with_missing_failed_and_unscored_sessions(copy_demo, changes):
    from metrics.reading.report import write_report
    from sessions.exchange.bundle_export import export_study
    from sessions.exchange.progress import progress_table, write_progress
    from sessions.exchange.xapi import XapiSettings, study_statements
    from sessions.scoring.analysis import analyse_catalog_study

    with tempfile.TemporaryDirectory() as folder:
        home = Path(folder) / "home"
        catalog = Catalog(copy_demo(home))
        try:
            count = change_sessions(catalog, changes)
            statements = study_statements(catalog, DEMO_STUDY, XapiSettings(home_page="https://sim.test"))
            for statement in statements:
                json.dumps(statement.body, allow_nan=False)  # valid JSON: no NaN anywhere
                score = statement.body.get("result", {}).get("score")
                if score is not None:
                    assert 0 <= score["raw"] <= score["max"] and math.isfinite(score["scaled"])
            table = progress_table(catalog, DEMO_STUDY)
            for suffix in (".csv", ".xlsx"):
                written = write_progress(table, Path(folder) / f"progress{suffix}", DEMO_STUDY)
                assert written.stat().st_size > 0
            summary = export_study(catalog, DEMO_STUDY, Path(folder) / "study.zip")
            assert summary["sessions"] == count
            analysis, _ = analyse_catalog_study(catalog, DEMO_STUDY, {})
            page = write_report(analysis, Path(folder) / "report", title=f"Study {DEMO_STUDY}")
            assert "Traceback" not in page.read_text()
        finally:
            catalog.close()
