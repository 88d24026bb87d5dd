"""Only marks that point the right way (issue 44, seen 2): a metric is benchmarked only where the
skilled group does better (oriented AUC above 0.5) and its participant-level interval excludes 0.5;
a declared metric whose interval includes 0.5 needs a stated reason; none qualifying means no
standard (nobody passes), never the largest effects whatever their sign; fewer experts than the
rule's minimum make the standard provisional."""

from __future__ import annotations

import numpy as np
import pandas as pd

from metrics.study.analysis import StudySettings, analyse_study
from metrics.study.proficiency import benchmarks_heading


def course(experts: int = 8, trainees: int = 8, sessions: int = 2) -> pd.DataFrame:
    """Participants' sessions with three metrics, built so the answer is known by construction:
    path_length (lower is better): experts 0.10-0.17 m, trainees 0.50-0.57 m (separate: experts better);
    task_time (lower is better): trainees faster (experts 40-47 s, trainees 10-17 s: trainees better);
    spectral_arc_length (higher is better): the two groups interleave (no difference)."""
    rows = []
    for group, count in (("expert", experts), ("trainee", trainees)):
        for p in range(count):
            for trial in range(1, sessions + 1):
                skilled = group == "expert"
                rows.append(
                    {
                        "session_id": f"{group[0]}{p}-{trial}",
                        "participant_id": f"{group[0].upper()}{p:02d}",
                        "label": group,
                        "trial": trial,
                        "path_length": (0.10 if skilled else 0.50) + 0.01 * p,
                        "task_time": (40.0 if skilled else 10.0) + p,
                        "spectral_arc_length": -3.0 - 0.1 * p - (0.05 if skilled else 0.0),
                    }
                )
    return pd.DataFrame(rows)


SETTINGS = StudySettings(metrics=("path_length", "task_time", "spectral_arc_length"), n_boot=200)


def test_a_metric_trainees_do_better_on_is_never_a_benchmark():
    analysis = analyse_study(course(), SETTINGS)
    validity = analysis.validity.table.set_index("metric")
    assert validity.at["task_time", "auc"] == 0.0 and validity.at["path_length", "auc"] == 1.0
    assert analysis.benchmarks["metric"].tolist() == ["path_length"]
    # the experts pass on the metric that separates; the trainees do not
    passed = analysis.proficiency.set_index(analysis.sessions["label"])["passed"]
    assert passed.loc["expert"].any() and not passed.loc["trainee"].any()


def test_declared_benchmarks_keep_the_direction_rule_and_an_override_needs_a_reason():
    declared = StudySettings(**{**SETTINGS.__dict__, "benchmark_metrics": SETTINGS.metrics})
    analysis = analyse_study(course(), declared)
    assert analysis.benchmarks["metric"].tolist() == ["path_length"]  # no reason: the overlap is refused
    refused = next(n for n in analysis.notes if n.startswith("Not benchmarked"))
    assert "task_time (experts do not do better: AUC 0.00)" in refused
    reason = "the course's agreed mark on smoothness (faculty meeting, 2026-11-30)"
    overridden = StudySettings(**{**declared.__dict__, "benchmark_override": reason})
    analysis = analyse_study(course(), overridden)
    validity = analysis.validity.table.set_index("metric")
    smooth_auc = validity.at["spectral_arc_length", "auc"]
    expected = ["path_length"] + (["spectral_arc_length"] if smooth_auc > 0.5 else [])
    assert analysis.benchmarks["metric"].tolist() == expected  # task_time never, whatever the reason
    if smooth_auc > 0.5:
        assert any(reason in n for n in analysis.notes)


def test_no_metric_qualifying_is_no_standard_and_nobody_passes():
    table = course()
    table["path_length"] = np.where(table["label"] == "expert", 0.9, 0.1)  # trainees better on both
    analysis = analyse_study(table, SETTINGS)
    assert analysis.benchmarks.empty and not analysis.proficiency["passed"].any()
    assert any(n.startswith("No standard:") for n in analysis.notes)
    assert "no standard" in benchmarks_heading(analysis.benchmarks, SETTINGS.min_experts)
    assert analysis.standards is None


def test_fewer_experts_than_the_rule_asks_make_the_standard_provisional():
    few = analyse_study(course(experts=4, trainees=8), SETTINGS)
    assert few.benchmarks["provisional"].all()
    assert benchmarks_heading(few.benchmarks, 5) == (
        "Proficiency benchmarks (provisional: 4 expert(s), the rule asks for 5)"
    )
    assert any("provisional: 4 expert(s) set them" in n for n in few.notes)
    enough = analyse_study(course(experts=6, trainees=8), SETTINGS)
    assert not enough.benchmarks["provisional"].any()
    assert benchmarks_heading(enough.benchmarks, 5) == "Proficiency benchmarks (from 6 experts)"
