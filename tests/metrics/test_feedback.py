"""What to work on: every metric has advice; worse-than-expert metrics ranked safety, quality,
efficiency and by distance outside the experts' band; the same lines in the CLI and the dashboard."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner
from fastapi.testclient import TestClient
from markupsafe import escape
from sqlalchemy import select

from dashboard.app import create_app
from dashboard.settings import DashboardSettings
from metrics.errors import MetricsError
from metrics.reading.feedback import (
    band_widths_outside,
    feedback_line,
    kind_of,
    metric_groups,
    session_feedback,
    strength_line,
    strengths,
    what_to_work_on,
)
from metrics.session.registry import REGISTRY, metric
from sessions.catalog import Catalog
from sessions.catalog.accounts import create_user
from sessions.catalog.models import Participant, Session
from sessions.cli import main
from sessions.scoring.review import against_band
from tests.dashboard.conftest import sign_in


def test_every_registered_metric_has_advice_and_no_other():
    assert all(m.advice.endswith(".") and len(m.advice) < 90 for m in REGISTRY)
    with pytest.raises(MetricsError, match="advice must be one sentence"):
        metric(
            "new_metric",
            unit="s",
            definition="d",
            advice="",
            better="lower",
            reference="r",
            group="g",
            kind="efficiency",
        )


def test_band_widths_outside_hand_worked():
    assert band_widths_outside(0.5, 0.1, 0.2, "lower") == pytest.approx(3.0)  # 0.3 beyond q3, band 0.1
    assert band_widths_outside(0.15, 0.1, 0.2, "lower") == 0.0
    assert band_widths_outside(-3.0, -2.5, -2.0, "higher") == pytest.approx(1.0)
    assert band_widths_outside(2.0, 0.0, 0.0, "lower") == 2.0  # two back-wall catches where experts had none


def test_ranking_puts_safety_first_then_quality_then_efficiency():
    band = {
        "back_wall_catches": {"expert_q1": 0.0, "expert_median": 0.0, "expert_q3": 0.0},
        "entry_to_target": {"expert_q1": 1e-4, "expert_median": 1.5e-4, "expert_q3": 2e-4},
        "exit_to_target": {"expert_q1": 1e-4, "expert_median": 1.5e-4, "expert_q3": 2e-4},
        "path_length": {"expert_q1": 0.02, "expert_median": 0.025, "expert_q3": 0.03},
        "task_time": {"expert_q1": 5.0, "expert_median": 6.0, "expert_q3": 7.0},
    }
    values = {
        "back_wall_catches": 1.0,  # a never event, however small
        "entry_to_target": 3e-4,  # 1 band width worse
        "exit_to_target": 6e-4,  # 4 band widths worse
        "path_length": 0.09,  # 6 band widths worse, but efficiency
        "task_time": 6.5,  # within
    }
    items = what_to_work_on(against_band(values, band), limit=3)
    assert [i["metric"] for i in items] == ["back_wall_catches", "exit_to_target", "entry_to_target"]
    assert [kind_of(i["metric"]) for i in items] == ["safety", "quality", "quality"]
    everything = what_to_work_on(against_band(values, band), limit=10)
    assert [i["metric"] for i in everything][-1] == "path_length" and len(everything) == 4
    line = feedback_line(items[1])
    assert line == (
        "Bring the needle out at the exit mark: rotate along its curve. "
        "(exit distance from its mark 0.6 mm; experts 0.1-0.2 mm, lower is better)"
    )
    only_safety = what_to_work_on(against_band(values, band), limit=0)
    assert [i["metric"] for i in only_safety] == ["back_wall_catches"]  # safety is never cut


def test_the_pass_marks_a_session_misses_lead_then_safety_then_the_rest():
    """Issue 44, seen 5: T01 is blocked by entry_to_target, yet "what to work on" listed three safety
    items and never the mark that stops them passing. The marks missed come first (the furthest
    from its mark first), each with the gap in display units, then the never events, then the rest."""
    import pandas as pd

    from metrics.study.proficiency import pass_condition

    band = {
        "back_wall_catches": {"expert_q1": 0.0, "expert_median": 0.0, "expert_q3": 0.0},
        "entry_to_target": {"expert_q1": 1e-4, "expert_median": 1.5e-4, "expert_q3": 2e-4},
        "exit_to_target": {"expert_q1": 1e-4, "expert_median": 1.5e-4, "expert_q3": 2e-4},
        "path_length": {"expert_q1": 0.02, "expert_median": 0.025, "expert_q3": 0.03},
        "peak_force": {"expert_q1": 0.8, "expert_median": 0.9, "expert_q3": 1.0},
        "task_time": {"expert_q1": 5.0, "expert_median": 6.0, "expert_q3": 7.0},
    }
    values = {
        "back_wall_catches": 1.0,
        "entry_to_target": 3e-4,  # misses its mark 0.173 mm by 0.127 mm (73 % of the mark)
        "exit_to_target": 6e-4,
        "path_length": 0.09,  # misses its mark 60 mm by 30 mm (50 %)
        "peak_force": 1.6,  # safety, worse than the experts, no mark
        "task_time": 4.0,  # meets its mark
    }
    marks = {"entry_to_target": 1.73e-4, "path_length": 0.06, "task_time": 6.0}
    benchmarks = pd.DataFrame(
        [
            {
                "metric": name,
                "benchmark": mark,
                "better": "lower",
                "pass_if": pass_condition(mark, "lower", REGISTRY[name].unit),
                "rule": "mean",
                "experts": 5,
            }
            for name, mark in marks.items()
        ]
    )
    feedback = session_feedback(against_band(values, band), limit=4, benchmarks=benchmarks)
    order = [(item["metric"], item["kind"]) for item in feedback["work_on"]]
    assert order == [
        ("entry_to_target", "benchmark"),
        ("path_length", "benchmark"),
        ("back_wall_catches", "safety"),
        ("peak_force", "safety"),
    ]
    assert feedback["work_on"][0]["line"] == (
        f"{REGISTRY['entry_to_target'].advice} (entry distance from its mark 0.3 mm; the pass mark is "
        "<= 0.173 mm: 0.127 mm to go)"
    )
    assert feedback["work_on"][1]["line"].endswith(
        "(path length 90 mm; the pass mark is <= 60 mm: 30 mm to go)"
    )
    without = session_feedback(against_band(values, band), limit=4)  # no standard: the band alone
    assert [item["kind"] for item in without["work_on"]][:2] == ["safety", "safety"]


def test_the_cli_and_the_session_page_say_the_same(tmp_path, copy_demo, monkeypatch):
    home = tmp_path / "home"
    url = copy_demo(home)
    monkeypatch.setenv("VASCSIM_HOME", str(home))
    monkeypatch.setenv("VASCSIM_DATABASE_URL", url)
    catalog = Catalog(url)
    with catalog.session() as orm:
        uid = orm.scalar(
            select(Session.uid).join(Participant).where(Participant.code == "T01").order_by(Session.trial)
        )
        create_user(orm, "supervisor", "correct horse battery", "supervisor")
    shown = json.loads(CliRunner().invoke(main, ["sessions", "show", uid, "--json"]).stdout)
    assert shown["work_on"], "a first-day trainee has something to work on"
    text = CliRunner().invoke(main, ["sessions", "show", uid], env={"COLUMNS": "80"}).stdout
    # hashes whole, each on its own line; only a path may be longer than the terminal
    assert max(len(line) for line in text.splitlines() if not line.startswith("directory")) <= 80
    lines = text.splitlines()
    assert lines.index("  safety") < lines.index("  quality and efficiency") < lines.index(next(
        line for line in lines if line.startswith("work on")
    ))  # fmt: skip
    for item in shown["work_on"] + shown["strengths"]:
        assert " ".join(item["line"].split()) in " ".join(text.split())
    app = create_app(DashboardSettings(home=home, database_url=url), catalog)
    with TestClient(app) as client:
        sign_in(client, "supervisor", "correct horse battery")
        page = client.get(f"/sessions/{uid}").text
    for item in shown["work_on"]:
        assert str(escape(item["line"])) in page
    for item in shown["strengths"]:
        assert str(escape(item["line"])) in page
    catalog.close()


def test_strengths_are_the_metrics_better_than_the_experts_then_safety_level_with_them():
    band = {
        "back_wall_catches": {"expert_q1": 0.0, "expert_median": 0.0, "expert_q3": 0.0},
        "entry_to_target": {"expert_q1": 1e-4, "expert_median": 1.5e-4, "expert_q3": 2e-4},
        "path_length": {"expert_q1": 0.02, "expert_median": 0.025, "expert_q3": 0.03},
        "task_time": {"expert_q1": 5.0, "expert_median": 6.0, "expert_q3": 7.0},
    }
    values = {"back_wall_catches": 0.0, "entry_to_target": 0.5e-4, "path_length": 0.01, "task_time": 6.0}
    rows = against_band(values, band)
    found = strengths(rows, limit=3)
    # better than the band: quality before efficiency; then the never event level with the experts
    assert [i["metric"] for i in found] == ["entry_to_target", "path_length", "back_wall_catches"]
    assert strength_line(found[0]) == (
        "Better than the experts' middle half: entry distance from its mark 0.05 mm "
        "(experts 0.1-0.2 mm, lower is better)"
    )
    assert strength_line(found[2]).startswith("Level with the experts: back wall catches 0 (experts 0,")
    assert not any(i["metric"] == "task_time" for i in strengths(rows, limit=10))  # level efficiency: no
    shown = session_feedback(rows)
    assert shown["work_on"] == [] and [i["metric"] for i in shown["strengths"]] == [
        "entry_to_target",
        "path_length",
    ]


def test_metrics_grouped_safety_first_then_quality_and_efficiency():
    values = {"task_time": 6.0, "peak_force": 0.8, "back_wall_catches": 0.0, "full_thickness_fraction": 1.0}
    groups = metric_groups(against_band(values, {}))
    assert [g["title"] for g in groups] == ["Safety", "Quality and efficiency"]
    assert [r["metric"] for r in groups[0]["metrics"]] == [
        "peak_force",
        "back_wall_catches",
        "full_thickness_fraction",
    ]
    assert [r["metric"] for r in groups[1]["metrics"]] == ["task_time"]
    assert [g["title"] for g in metric_groups(against_band({"task_time": 6.0}, {}))] == [
        "Quality and efficiency"
    ]


def test_never_events_outrank_the_rest_of_safety():
    band = {
        "wound_edge_stress": {"expert_q1": 1e5, "expert_median": 2e5, "expert_q3": 3e5},
        "force_clamp_hits": {"expert_q1": 0.0, "expert_median": 0.0, "expert_q3": 0.0},
    }
    values = {"wound_edge_stress": 3e6, "force_clamp_hits": 1.0}  # 13.5 widths against 1
    items = what_to_work_on(against_band(values, band), limit=1)
    assert [i["metric"] for i in items] == [
        "force_clamp_hits"
    ]  # the never event is kept, the limit is filled
    assert [i["kind"] for i in what_to_work_on(against_band(values, band), limit=5)] == ["safety", "safety"]


def test_each_metric_says_its_kind_where_it_registers():
    """Issue 48: what harms the patient is a property of the metric (``@metric(kind=...)``), not a
    list of names kept in the feedback module: the safety kind is the never events, partial-thickness
    bites and extra punctures, excessive force, the tissue's load and the forceps' harm; placement is
    quality; the rest efficiency. A metric without a known kind is refused as it registers."""
    from metrics.study.standards import SAFETY_METRICS

    kinds = REGISTRY.describe().set_index("name")["kind"]
    assert set(kinds) == {"safety", "quality", "efficiency"}
    assert set(kinds[kinds == "safety"].index) == {
        *SAFETY_METRICS,
        "full_thickness_fraction",
        "extra_punctures",
        "peak_force",
        "wound_edge_stress",
        "high_stress_area",
        "stress_concentration",
        "peak_stretch",
        "time_above_strain_limit",
        "forceps_tears",
        "peak_grasp_force",
    }
    quality = {m.name for m in REGISTRY if m.group == "placement"} - set(kinds[kinds == "safety"].index)
    assert set(kinds[kinds == "quality"].index) == quality
    assert kind_of("a_column_someone_imported") == "efficiency"
    with pytest.raises(MetricsError, match="kind must be one of safety, quality, efficiency"):
        metric(
            "a_metric_of_no_known_kind",
            unit="1",
            definition="-",
            advice="Do better.",
            better="lower",
            reference="-",
            group="motion",
            kind="speed",
        )(lambda context: 0.0)
