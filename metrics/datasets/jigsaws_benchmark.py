"""The public JIGSAWS skill benchmark, run on vascsim's interpretable metrics, honestly.

Protocols (Gao et al. 2014; Ahmidi et al. 2017, IEEE TBME 64:2025):

- **LOSO**, leave one supertrial out: five folds, fold k tests every surgeon's k-th trial. A
  surgeon's other trials are in training, so the model can learn who a surgeon is rather than
  how skilled: subject identity leaks, and LOSO figures are optimistic.
- **LOUO**, leave one user out: eight folds (Suturing), fold k tests every trial of one surgeon.
  The honest protocol for a new trainee; with 2 experts and 4 novices a participant-level
  test cannot reach p below 2 / C(6, 2) = 0.133 (two-sided), whatever the features.

Folds come from the data set's own ``Experimental_setup/<Task>/{unBalanced,Balanced}/
{SkillDetection,GestureClassification}/{SuperTrialOut,UserOut}/<k>_Out/itr_1/Test.txt`` when
present (their first token names a trial or a segment of one, ``<Task>_<Surgeon><Trial>[_s_e].txt``),
else are built from the trial names the same way. In every fold the metrics are standardised
on the training trials only and a logistic regression (scikit-learn defaults, no tuning on the
test fold) predicts novice / intermediate / expert (3-class) and novice vs expert (2-class, the
intermediates left out); a ridge regression (alpha 1) predicts the GRS total (Spearman's rho of
the pooled predictions). Intervals: percentile bootstrap resampling surgeons (2,000 draws).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

from metrics import compute_session_metrics
from metrics.datasets.jigsaws import Trial
from metrics.errors import MetricsError
from metrics.session.registry import REGISTRY

PROTOCOLS = ("LOSO", "LOUO")
SETUP_NAMES = {"LOSO": "SuperTrialOut", "LOUO": "UserOut"}
CLASSES_3 = ("novice", "intermediate", "expert")
CLASSES_2 = ("novice", "expert")
PUBLISHED = (
    # (protocol, classes, accuracy %, what, reference): printed beside ours, labelled as published
    ("LOSO", 3, 100.0, "approximate-entropy features", "Zia & Essa 2018, IJCARS 13:731"),
    ("LOSO", 3, 98.4, "CNN-LSTM on kinematics", "Nguyen et al. 2019, Comput Methods Programs Biomed 177:1"),
    ("LOSO", 3, 92.5, "CNN on short windows", "Wang & Fey 2018, IJCARS 13:1959"),
    ("LOSO", 2, 89.9, "eight global movement features", "Fard et al. 2018, IJMRCAS 14:e1850"),
)


@dataclass(frozen=True)
class Fold:
    name: str
    test: tuple[str, ...]  # trial ids
    train: tuple[str, ...]


def built_folds(trials: list[Trial], protocol: str) -> list[Fold]:
    """The protocol's folds from the trial names: LOSO by trial number, LOUO by surgeon."""
    if protocol not in PROTOCOLS:
        raise MetricsError(f"protocol must be one of {', '.join(PROTOCOLS)}; got {protocol!r}")
    key = (lambda t: t.trial) if protocol == "LOSO" else (lambda t: t.participant_id)
    groups: dict[object, list[str]] = {}
    for trial in trials:
        groups.setdefault(key(trial), []).append(trial.trial_id)
    every = [t.trial_id for t in trials]
    return [
        Fold(f"{k}_Out", tuple(test), tuple(t for t in every if t not in set(test)))
        for k, test in sorted(groups.items(), key=lambda item: str(item[0]))
    ]


def _trial_of(token: str, known: set[str]) -> str | None:
    name = Path(token).name
    if name.endswith(".txt"):
        name = name[:-4]
    if name in known:
        return name
    parts = name.split("_")
    if len(parts) >= 4 and "_".join(parts[:-2]) in known:  # a segment: <trial>_<start>_<end>
        return "_".join(parts[:-2])
    return None


def setup_folds(root: Path, task: str, protocol: str, trials: list[Trial]) -> list[Fold] | None:
    """The folds of the data set's own split files under ``root`` (the folder holding
    ``Experimental_setup``, or that folder itself), or None when it has none for this task."""
    base = root / "Experimental_setup" if (root / "Experimental_setup").is_dir() else root
    known = {t.trial_id for t in trials}
    for balance in ("unBalanced", "Balanced"):
        for purpose in ("SkillDetection", "GestureClassification"):
            folder = base / task / balance / purpose / SETUP_NAMES[protocol]
            if not folder.is_dir():
                continue
            folds = []
            for out in sorted(folder.glob("*_Out"), key=lambda p: (len(p.name), p.name)):
                files = {p.name.lower(): p for p in (out / "itr_1").glob("*.txt")}
                if "test.txt" not in files:
                    raise MetricsError(f"{out / 'itr_1'}: no Test.txt in the data set's split folder")
                test = []
                for number, line in enumerate(files["test.txt"].read_text(errors="replace").splitlines(), 1):
                    if not line.strip():
                        continue
                    trial = _trial_of(line.split()[0], known)
                    if trial is None:
                        raise MetricsError(
                            f"{files['test.txt']}, line {number}: {line.split()[0]!r} names no trial "
                            "of this task"
                        )
                    if trial not in test:
                        test.append(trial)
                folds.append(
                    Fold(out.name, tuple(test), tuple(t.trial_id for t in trials if t.trial_id not in test))
                )
            if folds:
                return folds
    return None


def check_folds(folds: list[Fold], trials: list[Trial]) -> None:
    """Every trial tested exactly once and never trained on in its own fold."""
    tested = [t for fold in folds for t in fold.test]
    every = {t.trial_id for t in trials}
    if sorted(tested) != sorted(every):
        missing = sorted(every - set(tested))
        raise MetricsError(
            "the folds do not test every trial exactly once"
            + (f" (never tested: {', '.join(missing[:3])})" if missing else " (a trial is tested twice)")
        )
    for fold in folds:
        if set(fold.test) & set(fold.train):
            raise MetricsError(f"fold {fold.name} trains on a trial it tests")


@dataclass
class ProtocolResult:
    protocol: str
    folds: int
    source: str  # "split files" (the data set's own) or "trial names" (built from them)
    accuracy_3: float
    accuracy_3_ci: tuple[float, float]
    macro_f1_3: float
    macro_f1_3_ci: tuple[float, float]
    confusion_3: pd.DataFrame
    accuracy_2: float
    accuracy_2_ci: tuple[float, float]
    macro_f1_2: float
    confusion_2: pd.DataFrame
    grs_rho: float
    grs_rho_ci: tuple[float, float]
    weights: pd.Series  # mean |standardised coefficient| per metric, 3-class, across folds


@dataclass
class BenchmarkResult:
    task: str
    trials: int
    surgeons: int
    metrics: list[str]
    protocols: dict[str, ProtocolResult]
    notes: list[str] = field(default_factory=list)

    def table(self) -> pd.DataFrame:
        """One row per protocol: accuracies, macro-F1 and GRS rho with their intervals."""
        rows = []
        for name, r in self.protocols.items():
            rows.append(
                {
                    "protocol": name,
                    "folds": r.folds,
                    "folds from": r.source,
                    "3-class accuracy": _pct(r.accuracy_3, r.accuracy_3_ci),
                    "3-class macro-F1": _num(r.macro_f1_3, r.macro_f1_3_ci),
                    "2-class accuracy": _pct(r.accuracy_2, r.accuracy_2_ci),
                    "GRS Spearman rho": _num(r.grs_rho, r.grs_rho_ci),
                }
            )
        return pd.DataFrame(rows)

    def published(self) -> pd.DataFrame:
        return pd.DataFrame(
            [
                {
                    "protocol": p,
                    "classes": c,
                    "accuracy (published)": f"{a:.1f} %",
                    "method": w,
                    "reference": ref,
                }
                for p, c, a, w, ref in PUBLISHED
            ]
        )


def _pct(value: float, ci: tuple[float, float]) -> str:
    if not math.isfinite(value):
        return "n/a"
    return f"{100 * value:.1f} % ({100 * ci[0]:.0f}-{100 * ci[1]:.0f} %)"


def _num(value: float, ci: tuple[float, float]) -> str:
    if not math.isfinite(value):
        return "n/a"
    return f"{value:.2f} ({ci[0]:.2f} to {ci[1]:.2f})"


def _macro_f1(truth: np.ndarray, predicted: np.ndarray, classes: tuple[str, ...]) -> float:
    """Macro-averaged F1 over the classes present in ``truth`` (a class never predicted and never
    true is left out; F1 0 where precision and recall are both 0), as scikit-learn's
    ``f1_score(average="macro", labels=present)``: in plain NumPy, called in every bootstrap draw."""
    scores = []
    for c in classes:
        is_true = truth == c
        if not is_true.any():
            continue
        is_predicted = predicted == c
        hits = float(np.sum(is_true & is_predicted))
        denominator = float(is_true.sum() + is_predicted.sum())
        scores.append(2 * hits / denominator if denominator else 0.0)
    return float(np.mean(scores)) if scores else math.nan


def _spearman(x: np.ndarray, y: np.ndarray) -> float:
    """Spearman's rho: Pearson's r of the mid-ranks (nan when either side is constant)."""
    rx, ry = stats.rankdata(x), stats.rankdata(y)
    rx, ry = rx - rx.mean(), ry - ry.mean()
    denominator = math.sqrt(float(rx @ rx) * float(ry @ ry))
    return float(rx @ ry) / denominator if denominator > 0 else math.nan


def _cluster_bootstrap(surgeon: np.ndarray, statistic, draws: int, seed: int) -> tuple[float, float]:
    """Percentile interval of ``statistic(index)`` over resamples of surgeons (with replacement)."""
    rng = np.random.default_rng(seed)
    names = np.unique(surgeon)
    rows = {s: np.flatnonzero(surgeon == s) for s in names}
    values = []
    for _ in range(draws):
        chosen = rng.choice(names, size=len(names), replace=True)
        index = np.concatenate([rows[s] for s in chosen])
        value = statistic(index)
        if math.isfinite(value):
            values.append(value)
    if not values:
        return math.nan, math.nan
    low, high = np.quantile(values, [0.025, 0.975])
    return float(low), float(high)


def _standardised(train: np.ndarray, test: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    centre = train.mean(axis=0)
    scale = train.std(axis=0)
    scale = np.where(scale > 0, scale, 1.0)
    return (train - centre) / scale, (test - centre) / scale


def run_protocol(
    table: pd.DataFrame,
    metrics: list[str],
    folds: list[Fold],
    source: str,
    protocol: str,
    draws: int,
    seed: int,
) -> ProtocolResult:
    """Fit and predict fold by fold; pool the test predictions; intervals by surgeon bootstrap."""
    from sklearn.linear_model import LogisticRegression, Ridge

    indexed = table.set_index("session_id")
    predicted_3 = pd.Series(index=indexed.index, dtype=object)
    predicted_2 = pd.Series(index=indexed.index, dtype=object)
    predicted_grs = pd.Series(index=indexed.index, dtype=float)
    weights = []
    for fold in folds:
        train = indexed.loc[list(fold.train)]
        test = indexed.loc[list(fold.test)]
        x_train, x_test = _standardised(train[metrics].to_numpy(float), test[metrics].to_numpy(float))
        labels = train["label"].to_numpy()
        if len(np.unique(labels)) >= 2:
            model = LogisticRegression(max_iter=5000).fit(x_train, labels)
            predicted_3.loc[list(fold.test)] = model.predict(x_test)
            weights.append(np.abs(model.coef_).mean(axis=0))
        two = np.isin(labels, CLASSES_2)
        testing_two = test["label"].isin(CLASSES_2).to_numpy()
        if len(np.unique(labels[two])) == 2 and testing_two.any():
            model2 = LogisticRegression(max_iter=5000).fit(x_train[two], labels[two])
            predicted_2.loc[test.index[testing_two]] = model2.predict(x_test[testing_two])
        ridge = Ridge(alpha=1.0).fit(x_train, train["grs"].to_numpy(float))
        predicted_grs.loc[list(fold.test)] = ridge.predict(x_test)
    truth = indexed["label"].to_numpy()
    surgeon = indexed["participant_id"].to_numpy()
    p3 = predicted_3.to_numpy()
    judged = pd.notna(p3)

    def accuracy(index: np.ndarray, predicted: np.ndarray, keep: np.ndarray) -> float:
        index = index[keep[index]]
        return float(np.mean(predicted[index] == truth[index])) if len(index) else math.nan

    every = np.arange(len(truth))
    accuracy_3 = accuracy(every, p3, judged)
    f1_3 = _macro_f1(truth[judged], p3[judged], CLASSES_3)
    p2 = predicted_2.to_numpy()
    judged_2 = pd.notna(p2)
    accuracy_2 = accuracy(every, p2, judged_2)
    f1_2 = _macro_f1(truth[judged_2], p2[judged_2], CLASSES_2) if judged_2.any() else math.nan
    grs = indexed["grs"].to_numpy(float)
    pg = predicted_grs.to_numpy(float)

    def rho(index: np.ndarray) -> float:
        return _spearman(grs[index], pg[index])

    return ProtocolResult(
        protocol,
        len(folds),
        source,
        accuracy_3,
        _cluster_bootstrap(surgeon, lambda i: accuracy(i, p3, judged), draws, seed),
        f1_3,
        _cluster_bootstrap(
            surgeon,
            lambda i: (
                _macro_f1(truth[i[judged[i]]], p3[i[judged[i]]], CLASSES_3) if judged[i].any() else math.nan
            ),
            draws,
            seed + 1,
        ),
        _confusion(truth[judged], p3[judged], CLASSES_3),
        accuracy_2,
        _cluster_bootstrap(surgeon, lambda i: accuracy(i, p2, judged_2), draws, seed + 2),
        f1_2,
        _confusion(truth[judged_2], p2[judged_2], CLASSES_2),
        rho(every),
        _cluster_bootstrap(surgeon, rho, draws, seed + 3),
        pd.Series(
            np.mean(weights, axis=0) if weights else np.full(len(metrics), np.nan), index=metrics
        ).sort_values(ascending=False),
    )


def _confusion(truth: np.ndarray, predicted: np.ndarray, classes: tuple[str, ...]) -> pd.DataFrame:
    frame = pd.DataFrame(0, index=[f"true {c}" for c in classes], columns=[f"predicted {c}" for c in classes])
    for t, p in zip(truth, predicted, strict=True):
        frame.loc[f"true {t}", f"predicted {p}"] += 1
    return frame


def benchmark_metrics(table: pd.DataFrame) -> list[str]:
    """The registry's metrics every trial has (JIGSAWS has no force, needle or tissue streams)."""

    names = [m.name for m in REGISTRY if m.name in table.columns]
    return [n for n in names if table[n].notna().all() and table[n].nunique() > 1]


def run_benchmark(
    trials: list[Trial],
    setup_root: Path | None = None,
    draws: int = 2000,
    seed: int = 0,
    table: pd.DataFrame | None = None,
) -> BenchmarkResult:
    """Both protocols on one task's trials (``table``: their metrics, computed here when not given)."""

    if not trials:
        raise MetricsError("the JIGSAWS benchmark needs trials")
    tasks = sorted({t.task for t in trials})
    if len(tasks) != 1:
        raise MetricsError(f"run the benchmark on one task at a time; got {', '.join(tasks)}")
    if table is None:
        table = compute_session_metrics([t.to_streams() for t in trials])
    table = table.copy()
    by_id = {t.trial_id: t for t in trials}
    table["grs"] = table["session_id"].map(lambda s: by_id[s].grs)
    table["label"] = table["session_id"].map(lambda s: by_id[s].skill_label)
    table["participant_id"] = table["session_id"].map(lambda s: by_id[s].participant_id)
    metrics = benchmark_metrics(table)
    if not metrics:
        raise MetricsError("no metric has a value for every trial")
    results = {}
    for protocol in PROTOCOLS:
        folds = setup_folds(setup_root, tasks[0], protocol, trials) if setup_root is not None else None
        source = "split files" if folds is not None else "trial names"
        folds = folds if folds is not None else built_folds(trials, protocol)
        check_folds(folds, trials)
        results[protocol] = run_protocol(table, metrics, folds, source, protocol, draws, seed)
    experts = len({t.participant_id for t in trials if t.skill_label == "expert"})
    novices = len({t.participant_id for t in trials if t.skill_label == "novice"})
    notes = [
        "LOSO keeps each surgeon's other trials in training: the model may learn who a surgeon is, "
        "not how skilled, so LOSO accuracy is optimistic. LOUO (a surgeon never seen in training) is "
        "the honest protocol for a new trainee.",
        f"With {experts} experts and {novices} novices, a participant-level comparison cannot reach p "
        f"below {_smallest_p(experts, novices):.3f} (two-sided exact), whatever the features.",
        "Published figures are the authors' own, on their features and models, mostly under LOSO; they "
        "are printed for orientation, not as a like-for-like comparison.",
    ]
    return BenchmarkResult(
        tasks[0], len(trials), len({t.participant_id for t in trials}), metrics, results, notes
    )


def _smallest_p(a: int, b: int) -> float:
    if a == 0 or b == 0:
        return math.nan
    return min(1.0, 2.0 / math.comb(a + b, a))
