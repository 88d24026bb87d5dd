"""The JIGSAWS skill benchmark on files written in the data set's format (the data set is not
shipped): the folds are exactly the protocols', the data set's own split files are honoured, and
each fold is standardised and fitted on its training trials only."""

import json

import numpy as np
import pytest
from click.testing import CliRunner
from sklearn.linear_model import LogisticRegression
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler

from metrics import compute_session_metrics
from metrics.datasets import jigsaws
from metrics.datasets.jigsaws_benchmark import (
    benchmark_metrics,
    built_folds,
    check_folds,
    run_benchmark,
    setup_folds,
)
from metrics.errors import MetricsError
from sessions.cli import main
from tests.metrics.test_jigsaws import write_trial

# JIGSAWS Suturing: 8 surgeons, 39 trials (surgeon H has 4); self-reported skill and GRS
SURGEONS = {
    "B": ("N", 5, 12),
    "C": ("I", 5, 17),
    "D": ("E", 5, 24),
    "E": ("E", 5, 23),
    "F": ("I", 5, 16),
    "G": ("N", 5, 11),
    "H": ("N", 4, 13),
    "I": ("N", 5, 10),
}
FRAMES = {"E": 150, "I": 220, "N": 300}  # experts finish sooner


def write_task(root, surgeons=SURGEONS):
    folder = root / "Suturing" / "kinematics" / "AllGestures"
    folder.mkdir(parents=True)
    lines = []
    for k, (surgeon, (skill, count, grs)) in enumerate(surgeons.items()):
        for trial in range(1, count + 1):
            name = f"Suturing_{surgeon}00{trial}"
            frames = FRAMES[skill] + 7 * trial + 3 * k
            write_trial(
                folder / f"{name}.txt",
                frames,
                0.008 + 0.002 * (skill != "E") + 0.0003 * trial,
                10 * k + trial,
            )
            items = "\t".join(str(v) for v in (2, 2, 2, 2, 2, grs - 10))
            lines.append(f"{name}\t\t{skill}\t{grs + trial % 2}\t\t{items}")
    meta = root / "Suturing" / "meta_file_Suturing.txt"
    meta.write_bytes(("\r\n".join(lines) + "\r\n").encode())
    return root / "Suturing", meta


@pytest.fixture(scope="module")
def task(tmp_path_factory):
    root = tmp_path_factory.mktemp("jigsaws")
    folder, meta = write_task(root)
    trials = jigsaws.load(folder, meta)
    return root, folder, meta, trials, compute_session_metrics(trials)


def test_the_protocols_folds_from_the_trial_names(task):
    _, _, _, trials, _ = task
    assert len(trials) == 39
    loso = built_folds(trials, "LOSO")
    assert [f.name for f in loso] == [f"{k}_Out" for k in range(1, 6)]
    for k, fold in enumerate(loso, start=1):  # supertrial k: every surgeon's k-th trial
        assert sorted(fold.test) == sorted(t.trial_id for t in trials if t.trial == k)
        assert set(fold.train) == {t.trial_id for t in trials} - set(fold.test)
    assert len(loso[4].test) == 7  # surgeon H has no fifth trial
    louo = built_folds(trials, "LOUO")
    assert len(louo) == 8
    for fold in louo:  # one surgeon's trials, none of theirs in training
        surgeons = {t.participant_id for t in trials if t.trial_id in fold.test}
        assert len(surgeons) == 1
        assert not any(t.participant_id in surgeons for t in trials if t.trial_id in fold.train)
    check_folds(loso, trials)
    check_folds(louo, trials)
    with pytest.raises(MetricsError, match="protocol"):
        built_folds(trials, "LOTO")


def write_split(root, protocol_folder, folds):
    """Experimental_setup/Suturing/unBalanced/GestureClassification/<protocol>/<k>_Out/itr_1, listing
    gesture segments (<trial>_<start>_<end>.txt) as the data set does."""
    base = root / "Experimental_setup" / "Suturing" / "unBalanced" / "GestureClassification" / protocol_folder
    for name, test, train in folds:
        folder = base / name / "itr_1"
        folder.mkdir(parents=True)
        for file, trials in (("Test.txt", test), ("Train.txt", train)):
            lines = [
                f"{t}_000010_000090.txt           G1\n{t}_000091_000140.txt           G2" for t in trials
            ]
            (folder / file).write_text("\n".join(lines) + "\n")


def test_the_data_sets_own_split_files_are_read_and_honoured(task, tmp_path):
    _, _, _, trials, _ = task
    folds = built_folds(trials, "LOUO")
    write_split(tmp_path, "UserOut", [(f.name, f.test, f.train) for f in folds])
    read = setup_folds(tmp_path, "Suturing", "LOUO", trials)
    assert [(f.name, sorted(f.test)) for f in read] == [(f.name, sorted(f.test)) for f in folds]
    assert setup_folds(tmp_path, "Suturing", "LOSO", trials) is None  # no SuperTrialOut here
    # a split the files define differently is used as written (two surgeons per fold)
    pairs = [
        ("1_Out", folds[0].test + folds[1].test, ()),
        ("2_Out", sum((f.test for f in folds[2:]), ()), ()),
    ]
    other = tmp_path / "other"
    write_split(other, "UserOut", pairs)
    assert [len(f.test) for f in setup_folds(other, "Suturing", "LOUO", trials)] == [10, 29]
    bad = tmp_path / "bad"
    write_split(bad, "UserOut", [("1_Out", ("Suturing_Z009",), ())])
    with pytest.raises(MetricsError, match="names no trial"):
        setup_folds(bad, "Suturing", "LOUO", trials)
    incomplete = tmp_path / "incomplete"
    write_split(incomplete, "UserOut", [("1_Out", folds[0].test, ())])
    with pytest.raises(MetricsError, match="every trial exactly once"):
        check_folds(setup_folds(incomplete, "Suturing", "LOUO", trials), trials)


def test_each_fold_is_fitted_on_its_training_trials_only(task):
    """The pooled LOUO predictions equal an independent scikit-learn pipeline (scaler + logistic
    regression) fitted fold by fold on the training trials; the confusion matrices count every
    trial once (the 2-class one leaves the intermediates out)."""
    _, _, _, trials, table = task
    result = run_benchmark(trials, draws=50, table=table)
    louo = result.protocols["LOUO"]
    assert louo.confusion_3.to_numpy().sum() == 39
    assert louo.confusion_2.to_numpy().sum() == 29  # 10 intermediate trials out
    metrics = benchmark_metrics(table.assign(label=[t.skill_label for t in trials]))
    assert metrics == result.metrics and "force_at_insertion" not in metrics  # no force in JIGSAWS
    indexed = table.set_index("session_id")
    labels = {t.trial_id: t.skill_label for t in trials}
    correct = 0
    for fold in built_folds(trials, "LOUO"):
        model = make_pipeline(StandardScaler(), LogisticRegression(max_iter=5000))
        model.fit(indexed.loc[list(fold.train), metrics].to_numpy(float), [labels[t] for t in fold.train])
        predicted = model.predict(indexed.loc[list(fold.test), metrics].to_numpy(float))
        correct += sum(p == labels[t] for p, t in zip(predicted, fold.test, strict=True))
    assert louo.accuracy_3 == pytest.approx(correct / 39, abs=1e-12)
    assert louo.accuracy_3_ci[0] <= louo.accuracy_3 <= louo.accuracy_3_ci[1]
    assert -1 <= louo.grs_rho <= 1 and louo.weights.index[0] in metrics
    assert any("LOUO" in note and "honest" in note for note in result.notes)
    assert any("0.133" in note for note in result.notes)  # 2 experts, 4 novices
    assert {"Zia & Essa 2018, IJCARS 13:731"} <= set(result.published()["reference"])


def test_the_cli_runs_the_benchmark_and_refuses_a_missing_folder(task):
    root, folder, _, _, _ = task
    result = CliRunner().invoke(main, ["benchmark", "jigsaws", str(folder), "--draws", "20", "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert set(data["protocols"]) == {"LOSO", "LOUO"} and data["trials"] == 39
    assert data["protocols"]["LOSO"]["folds"] == 5 and data["protocols"]["LOUO"]["folds"] == 8
    shown = CliRunner().invoke(main, ["benchmark", "jigsaws", str(folder), "--draws", "20"])
    assert "honest" in shown.output and "Published figures" in shown.output
    assert all(len(line) <= 80 for line in shown.output.splitlines())
    missing = CliRunner().invoke(main, ["benchmark", "jigsaws", str(root / "nope")])
    assert missing.exit_code == 1 and "no JIGSAWS task folder" in missing.output
    assert len(missing.output.strip().splitlines()) == 1


def test_the_bootstraps_fast_statistics_equal_scikit_learn_and_scipy():
    from scipy import stats
    from sklearn.metrics import f1_score

    from metrics.datasets.jigsaws_benchmark import CLASSES_3, _macro_f1, _spearman

    rng = np.random.default_rng(2)
    for _ in range(50):
        truth = rng.choice(CLASSES_3, size=20)
        predicted = rng.choice(CLASSES_3, size=20)
        present = [c for c in CLASSES_3 if np.any(truth == c)]
        expected = f1_score(truth, predicted, labels=present, average="macro", zero_division=0)
        assert _macro_f1(truth, predicted, CLASSES_3) == pytest.approx(expected, abs=1e-12)
        x, y = rng.integers(0, 5, 15).astype(float), rng.normal(size=15)
        assert _spearman(x, y) == pytest.approx(stats.spearmanr(x, y).statistic, abs=1e-12)
