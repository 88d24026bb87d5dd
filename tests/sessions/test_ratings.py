"""Ratings through the CLI on a real catalog (SQLite and PostgreSQL): stored per rater and item,
checked against the instrument before anything is stored, and analysed for rater agreement."""

import json

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from metrics.datasets.jigsaws import GRS_ITEMS
from metrics.study.reliability import intraclass_correlation
from sessions.cli import main
from tests.metrics.test_jigsaws import TRIALS, write_trial


def invoke(*args):
    return CliRunner().invoke(main, list(args), catch_exceptions=False)


@pytest.fixture
def sessions(home, tmp_path):
    """Seven JIGSAWS-format trials imported into study "jigsaws" (its GRS by rater JIGSAWS)."""
    folder = tmp_path / "Suturing" / "kinematics" / "AllGestures"
    folder.mkdir(parents=True)
    lines = []
    for surgeon, (skill, grs, count) in TRIALS.items():
        for trial in range(1, count + 1):
            name = f"Suturing_{surgeon}00{trial}"
            write_trial(folder / f"{name}.txt", 90 + 30 * trial, 0.01 + 0.002 * trial, trial)
            items = "\t".join(str(v) for v in (2, 2, 2, 2, 2, grs - 10))
            lines.append(f"{name}\t\t{skill}\t{grs}\t\t{items}")
    meta = tmp_path / "Suturing" / "meta_file_Suturing.txt"
    meta.write_bytes(("\r\n".join(lines) + "\r\n").encode())
    assert invoke("import", str(tmp_path / "Suturing"), str(meta), "--study", "jigsaws").exit_code == 0
    return sorted(row["session"] for row in json.loads(invoke("sessions", "list", "--json").stdout))


def listed(instrument="GRS"):
    return json.loads(
        invoke("ratings", "list", "--study", "jigsaws", "--instrument", instrument, "--json").stdout
    )


def test_a_rating_is_stored_per_item_with_its_total_and_bad_ratings_store_nothing(sessions):
    first = sessions[0]
    ok = invoke("ratings", "add", first, "--rater", "Dr A", "--instrument", "grs", "--scores", "4,3,4,3,4,5")
    assert ok.exit_code == 0 and "GRS 23 (of 6-30) by Dr A" in ok.output
    before = listed()
    refusals = [
        (["--scores", "4,3,4,3,4"], "needs 6 comma-separated scores"),
        (["--scores", "4,3,4,3,4,6"], "not a whole score from 1 to 5"),
        (["--scores", "4,3,4,3,4,2.5"], "not a whole score from 1 to 5"),
        (["--item", "respect_for_tissue=4"], "missing item(s)"),
        (["--item", "bedside_manner=4"], "has no item 'bedside_manner'"),
    ]
    for extra, message in refusals:
        result = CliRunner().invoke(
            main, ["ratings", "add", first, "--rater", "Dr B", "--instrument", "GRS", *extra]
        )
        assert result.exit_code == 1 and message in result.output, result.output
        assert len(result.output.strip().splitlines()) == 1
    again = CliRunner().invoke(
        main, ["ratings", "add", first, "--rater", "Dr A", "--instrument", "GRS", "--scores", "1,1,1,1,1,1"]
    )
    assert again.exit_code == 1 and "already rated" in again.output and "--replace" in again.output
    unknown = CliRunner().invoke(
        main, ["ratings", "add", "nope", "--rater", "Dr A", "--instrument", "GRS", "--scores", "1,1,1,1,1,1"]
    )
    assert unknown.exit_code == 1 and "no session 'nope'" in unknown.output
    assert listed() == before  # nothing stored by any refusal
    replaced = invoke(
        "ratings",
        "add",
        first,
        "--rater",
        "Dr A",
        "--instrument",
        "GRS",
        "--scores",
        "1,1,1,1,1,1",
        "--replace",
    )
    assert replaced.exit_code == 0
    mine = [row for row in listed() if row["rater"] == "Dr A"]
    assert len(mine) == 1 and mine[0]["total"] == 6.0


def test_a_csv_import_is_all_or_nothing(sessions, tmp_path):
    header = "session_id,rater,instrument," + ",".join(GRS_ITEMS)
    good = [f"{s},Dr C,GRS,3,3,3,3,3,{k % 5 + 1}" for k, s in enumerate(sessions)]
    bad = tmp_path / "bad.csv"
    bad.write_text("\n".join([header, *good[:3], f"{sessions[3]},Dr C,GRS,3,3,3,3,3,9", *good[4:]]) + "\n")
    before = listed()
    refused = CliRunner().invoke(main, ["ratings", "import", str(bad)])
    assert refused.exit_code == 1 and "line 5" in refused.output and "not a whole score" in refused.output
    assert listed() == before
    duplicate = tmp_path / "duplicate.csv"
    duplicate.write_text("\n".join([header, good[0], good[0]]) + "\n")
    twice = CliRunner().invoke(main, ["ratings", "import", str(duplicate)])
    assert twice.exit_code == 1 and "rates session" in twice.output and "twice" in twice.output
    extra = tmp_path / "extra.csv"
    extra.write_text(header + ",bribe\n" + good[0] + ",5\n")
    assert "has no item 'bribe'" in CliRunner().invoke(main, ["ratings", "import", str(extra)]).output
    garbage = tmp_path / "garbage.csv"
    garbage.write_bytes(b"\xff\xfe\x00binary")
    assert "not UTF-8" in CliRunner().invoke(main, ["ratings", "import", str(garbage)]).output
    assert listed() == before
    path = tmp_path / "good.csv"
    path.write_text("\n".join([header, *good]) + "\n")
    assert invoke("ratings", "import", str(path)).exit_code == 0
    assert sum(row["rater"] == "Dr C" for row in listed()) == len(sessions)


def test_rater_agreement_from_the_catalog_is_the_icc_of_the_stored_totals(sessions, tmp_path):
    """Two more raters score every session; the CLI's ICC(2,1) of the totals equals the statistic
    on the stored table, and the study report carries the inter-rater table."""
    rng = np.random.default_rng(4)
    header = "session_id,rater,instrument," + ",".join(GRS_ITEMS)
    rows, totals = [header], {}
    for rater in ("Dr D", "Dr E"):
        for session in sessions:
            scores = rng.integers(2, 6, size=6)
            rows.append(f"{session},{rater},GRS," + ",".join(map(str, scores)))
            totals[(session, rater)] = int(scores.sum())
    path = tmp_path / "raters.csv"
    path.write_text("\n".join(rows) + "\n")
    assert invoke("ratings", "import", str(path)).exit_code == 0
    result = json.loads(invoke("ratings", "reliability", "--study", "jigsaws", "--json").stdout)
    total = next(row for row in result if row["item"] == "total")
    stored = pd.DataFrame(listed()).pivot(index="session_id", columns="rater", values="total")
    expected = intraclass_correlation(stored[["Dr D", "Dr E", "JIGSAWS"]].to_numpy())["ICC(2,1)"]
    assert total["sessions"] == len(sessions) and total["block_raters"] == 3
    assert total["icc21"] == pytest.approx(expected.value, abs=1e-12)
    shown = invoke("ratings", "reliability", "--study", "jigsaws")
    assert "ICC(2,1)" in shown.output and "Koo & Li" in shown.output
    assert all(len(line) <= 80 for line in shown.output.splitlines())
    out = tmp_path / "report"
    report = invoke("report", "--study", "jigsaws", "--groups", "expert,novice", "--out", str(out))
    assert report.exit_code == 0, report.output
    page = (out / "report.html").read_text()
    assert "Inter-rater agreement: GRS" in page and "Test-retest" in page
    # standard setting is shown for a standard; with too few participants for an AUC interval there is
    # none, and the page says so (issue 44: never a mark that may not separate the groups)
    has_standard = "Proficiency benchmarks: no standard" not in page
    assert ("Standard setting" in page) == has_standard
    assert (out / "tables" / "inter_rater_grs.csv").is_file()
