"""Construct validity on the trainees' baseline (issue 44, seen 7): a course whose trainees practise
to the experts' level stops showing a group difference over all their sessions, so no metric
qualifies for a standard and nobody can pass. Comparing the experts with each trainee's first N
practice sessions (declared in advance, ``baseline_trials``) asks the question construct validity
asks: do the metrics tell the skilled from the unpractised?"""

from __future__ import annotations

import pandas as pd
import pytest

from metrics.reading.report import write_report
from metrics.study.analysis import StudySettings, analyse_study
from sessions.catalog import CatalogError
from sessions.scoring.analysis import settings_from_json


def learning_course(experts: int = 6, trainees: int = 6, trials: int = 10) -> pd.DataFrame:
    """path_length (lower is better): each expert steady at 0.095-0.15 m; each trainee from 0.57-0.62 m
    halving its gap to 0.07-0.12 m every trial, so over all sessions the trainees' medians sit among
    the experts' while their first two sessions are far worse."""
    rows = []
    for group, count in (("expert", experts), ("trainee", trainees)):
        for p in range(count):
            level = 0.10 + 0.01 * p
            for trial in range(1, trials + 1):
                value = level if group == "expert" else level - 0.03 + 0.5 * 0.5 ** (trial - 1)
                rows.append(
                    {
                        "session_id": f"{group[0]}{p}-{trial}",
                        "participant_id": f"{group[0].upper()}{p:02d}",
                        "label": group,
                        "trial": trial,
                        "path_length": value if group == "trainee" or trial % 2 else level - 0.005,
                    }
                )
    return pd.DataFrame(rows)


SETTINGS = StudySettings(metrics=("path_length",), n_boot=200)


def test_trainees_who_reach_the_experts_hide_the_difference_over_all_their_sessions():
    analysis = analyse_study(learning_course(), SETTINGS)
    row = analysis.validity.table.set_index("metric").loc["path_length"]
    assert row["auc_ci_low"] <= 0.5  # the medians of 10 sessions overlap: no standard can be set
    assert analysis.benchmarks.empty
    assert not analysis.proficiency["passed"].any()


def test_the_baseline_separates_them_and_the_standard_follows():
    settings = StudySettings(**{**SETTINGS.__dict__, "baseline_trials": 2})
    analysis = analyse_study(learning_course(), settings)
    row = analysis.validity.table.set_index("metric").loc["path_length"]
    assert row["auc"] == 1.0 and row["auc_ci_low"] > 0.5
    # the experts' every session and the trainees' first two only
    assert analysis.validity.n_sessions == {"expert": 60, "trainee": 12}
    assert analysis.benchmarks["metric"].tolist() == ["path_length"]
    # the marks still come from every expert session, and every trainee session is still judged
    passed = analysis.proficiency.set_index(analysis.sessions["trial"])["passed"]
    trainee = (analysis.sessions["label"] == "trainee").to_numpy()
    assert not passed[trainee].loc[1].any() and passed[trainee].loc[10].all()
    assert any("first 2 practice session(s)" in note for note in analysis.notes)


def test_retention_sessions_are_not_baseline_and_a_short_record_counts_what_it_has():
    table = learning_course(trials=3)
    extra = table[table["trial"] == 3].copy()
    extra["trial"], extra["phase"] = 4, "retention"
    extra["session_id"] = extra["session_id"] + "r"
    table = pd.concat([table.assign(phase="practice"), extra], ignore_index=True)
    settings = StudySettings(**{**SETTINGS.__dict__, "baseline_trials": 5})
    analysis = analyse_study(table, settings)
    assert analysis.validity.n_sessions == {"expert": 18, "trainee": 18}  # all 3 practice, no retention


def test_the_report_says_what_was_compared(tmp_path):
    settings = StudySettings(**{**SETTINGS.__dict__, "baseline_trials": 2})
    report = write_report(analyse_study(learning_course(), settings), tmp_path)
    assert "first 2 practice session(s) each: their baseline" in report.read_text()


@pytest.mark.parametrize("value", [0, -1, 1.5, True, "2"])
def test_a_declared_baseline_must_be_a_whole_number_of_sessions(value):
    with pytest.raises(CatalogError, match=r"baseline_trials must be a whole number >= 1 or null"):
        settings_from_json({"baseline_trials": value}, "study 'x'")
    assert settings_from_json({"baseline_trials": None}, "x").baseline_trials is None
    assert settings_from_json({"baseline_trials": 3}, "x").baseline_trials == 3
