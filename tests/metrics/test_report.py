"""The study report from a synthetic study: files, numbers matching the tables, synthetic label."""

import math

import numpy as np
import pandas as pd
import pytest
from markupsafe import escape

from metrics import compute_session_metrics
from metrics.reading.report import write_report
from metrics.session.registry import REGISTRY_VERSION, display_name
from metrics.study.analysis import StudySettings, analyse_study
from metrics.synthetic import synthetic_study

PRIMARY = ("path_length", "spectral_arc_length", "entry_angle_error_deg", "force_at_insertion")


@pytest.fixture(scope="module")
def analysis():
    table = compute_session_metrics(synthetic_study(experts=5, trainees=6, duration=24, rate=250))
    return analyse_study(table, StudySettings(metrics=PRIMARY, n_boot=300))


def test_report_files_and_synthetic_label(analysis, tmp_path):
    page = write_report(analysis, tmp_path / "report", title="Demo study")
    folder = page.parent
    expected = ["report.html", "report.md", "figures/box_plots.png", "figures/box_plots.svg"]
    tables = ("construct_validity", "session_metrics", "benchmarks", "trainees")
    expected += ["figures/roc.svg", *(f"tables/{n}.csv" for n in tables)]
    for name in expected:
        assert (folder / name).is_file(), name
    assert (folder / "figures/learning_curves.svg").is_file()
    text = page.read_text()
    assert "Synthetic data" in text and "Analysis level: participant" in text
    assert "Synthetic data" in (folder / "report.md").read_text()
    # issue 25, seen: the report said neither when it was made nor by which version
    from importlib.metadata import version

    stamp = f"by vascsim {version('vascsim')}, metric registry version {REGISTRY_VERSION}."
    assert "Generated 20" in text and stamp in text and stamp in (folder / "report.md").read_text()
    validity = pd.read_csv(folder / "tables/construct_validity.csv")
    np.testing.assert_allclose(validity["auc"], analysis.validity.table["auc"])
    assert set(validity["metric"]) == set(PRIMARY)


def test_primary_metrics_discriminate_and_trainees_get_a_status(analysis):
    assert set(analysis.validity.discriminating()) == set(PRIMARY)  # 5 v 6, 4 metrics: attainable after Holm
    assert len(analysis.trainees) == 6
    assert set(analysis.benchmarks["metric"]) == set(PRIMARY)
    assert "retention_passed" in analysis.trainees.columns
    assert analysis.validity.composite.auc == pytest.approx(1.0)


def test_the_trainee_table_reads_in_words_and_display_units(analysis):
    """Issue 25: the report's trainee table was 2,281 px wide of raw columns; it now says each trainee's
    status in words and the retention changes in display units with unit and direction."""
    from metrics.reading.tables import trainee_summary

    table = trainee_summary(analysis).set_index("trainee")
    raw = analysis.trainees.set_index("participant_id")
    assert list(table.index) == list(raw.index)
    for code, row in raw.iterrows():
        shown = table.loc[code]
        proficient = f"yes, at trial {int(row['trials_to_proficiency'])}" if row["proficient"] else "not yet"
        assert shown["proficient"] == proficient and shown["at the benchmark"] == row["passes"]
        session = shown["retention session"]
        assert session.startswith(
            "at the benchmark" if row["retention_passed"] else "worse than the benchmark"
        )
    header = "path length change (mm, lower is better)"
    assert table[header].to_numpy() == pytest.approx(1e3 * raw["retention_change_path_length"].to_numpy())


def test_participant_feedback_is_the_median_of_the_last_practice_sessions_against_the_experts(analysis):
    from metrics.reading.band import against_band
    from metrics.reading.feedback import participant_feedback, what_to_work_on

    table = analysis.sessions
    code = analysis.trainees["participant_id"].iloc[0]
    found = participant_feedback(analysis, code)
    mine = table[(table["participant_id"] == code) & (table["phase"].fillna("practice") != "retention")]
    last = mine.sort_values("trial").tail(3)
    assert found["trials"] == last["trial"].astype(int).tolist()
    # an independent reading: numpy quartiles of every expert session, the trainee's medians
    experts = table[table["label"] == "expert"]
    worse = []
    for name in PRIMARY:
        q1, q3 = np.nanquantile(experts[name].to_numpy(float), [0.25, 0.75])
        value = float(np.nanmedian(last[name].to_numpy(float)))
        better = "lower" if name != "spectral_arc_length" else "higher"
        if (value > q3) if better == "lower" else (value < q1):
            worse.append(name)
    listed = {item["metric"] for item in found["work_on"]}
    assert listed & set(PRIMARY) <= set(worse) and listed, "a first-week synthetic trainee has work to do"
    values = {n: float(np.nanmedian(last[n].to_numpy(float))) for n in PRIMARY}
    band = {
        n: dict(
            zip(
                ("expert_q1", "expert_median", "expert_q3"),
                np.nanquantile(experts[n], [0.25, 0.5, 0.75]),
                strict=True,
            )
        )
        for n in PRIMARY
    }
    assert {i["metric"] for i in what_to_work_on(against_band(values, band), limit=10)} == set(worse)


def test_the_report_lists_each_trainees_feedback_and_its_csvs_say_their_units(analysis, tmp_path):
    from metrics.reading.feedback import participant_feedback

    page = write_report(analysis, tmp_path / "report")
    text = page.read_text()
    code = analysis.trainees["participant_id"].iloc[0]
    assert "What each trainee should work on next" in text
    for item in participant_feedback(analysis, code)["work_on"]:
        assert str(escape(item["line"])) in text
    sessions = pd.read_csv(page.parent / "tables/session_metrics.csv")
    assert {"path_length [m]", "entry_angle_error_deg [deg]", "force_at_insertion [N]"} <= set(
        sessions.columns
    )
    np.testing.assert_allclose(sessions["path_length [m]"], analysis.sessions["path_length"])  # SI kept
    benchmarks = pd.read_csv(page.parent / "tables/benchmarks.csv")
    assert dict(zip(benchmarks["metric"], benchmarks["unit"].astype(str), strict=True)) == {
        "path_length": "m",
        "spectral_arc_length": "1",  # dimensionless, as registry.csv says
        "entry_angle_error_deg": "deg",
        "force_at_insertion": "N",
    }
    assert "spectral_arc_length" in sessions.columns  # a ratio keeps its bare name
    trainees = pd.read_csv(page.parent / "tables/trainees.csv")
    assert "retention_change_path_length [m]" in trainees.columns
    # the page shows the pass condition in display units, not the SI mark
    assert "a session passes when" in text and " mm</td>" in text


def test_concurrent_validity_reads_rho_with_its_interval_and_no_metric_unit():
    from metrics.reading.tables import concurrent_for_reading

    table = pd.DataFrame(
        [
            {"metric": "path_length", "unit": "m", "better": "lower", "n": 10, "rho": 0.646,
             "rho_ci_low": -0.0797, "rho_ci_high": 0.981, "p_value": 0.046, "p_holm": 0.138, "agrees": False},
            {"metric": "task_time", "unit": "s", "better": "lower", "n": 3, "rho": 0.5,
             "rho_ci_low": math.nan, "rho_ci_high": math.nan, "p_value": 0.6, "p_holm": 0.6, "agrees": False},
        ]
    )  # fmt: skip
    shown = concurrent_for_reading(table)
    assert "unit" not in shown.columns  # rho has none; the metric's unit read as if it were rho's
    column = "Spearman rho, better with a higher rating (95 % CI)"
    assert shown[column].tolist() == ["0.65 (-0.08 to 0.98)", "0.50 (too few participants for an interval)"]
    # issue 44, seen 10: the names a person reads, not the registry's keys
    assert shown["metric"].tolist() == [display_name("path_length"), display_name("task_time")]
    assert "path_length" not in shown["metric"].tolist()


def test_the_composite_weights_read_as_metric_names_with_the_way_the_experts_lie(analysis, tmp_path):
    """Seen in the report: the composite's weight table listed metric keys (``path_length``) and bare
    signed numbers; it now names each metric in words and says whether the experts' values are higher
    or lower, largest weight first, and the same table is in the Markdown report."""
    from metrics.reading.tables import composite_weights_for_reading

    weights = analysis.validity.composite.weights
    table = composite_weights_for_reading(analysis.validity.composite, "expert")
    carried = weights[weights.abs() > 0]
    assert list(table.columns) == ["metric", "weight", "expert values"]
    assert len(table) == len(carried) > 0
    assert set(table["metric"]) == {display_name(m) for m in carried.index}
    assert not set(table["metric"]) & set(PRIMARY)  # names, not keys
    sizes = [abs(float(w)) for w in table["weight"]]
    assert sizes == sorted(sizes, reverse=True)
    for name, weight, side in table.itertuples(index=False):
        key = next(m for m in carried.index if display_name(m) == name)
        assert float(weight) == pytest.approx(carried[key], abs=0.005)
        assert side == ("higher" if carried[key] > 0 else "lower")
    # path length: experts move less, so their values are lower and the weight negative
    assert table.set_index("metric").at[display_name("path_length"), "expert values"] == "lower"
    page = write_report(analysis, tmp_path / "report", title="Demo study")
    for text in (page.read_text(), (page.parent / "report.md").read_text()):
        assert str(escape(display_name("path_length"))) in text or display_name("path_length") in text
        assert "expert values" in text
    assert composite_weights_for_reading(None).empty
