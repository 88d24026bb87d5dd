"""Reliability statistics against published worked examples and independent implementations
(pingouin's intraclass_corr and cronbach_alpha, the krippendorff package)."""

import math
import warnings

import krippendorff
import numpy as np
import pandas as pd
import pingouin
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from metrics.errors import MetricsError
from metrics.study.reliability import (
    complete_block,
    cronbach_alpha,
    intraclass_correlation,
    krippendorff_alpha,
    test_retest,
)

# Shrout & Fleiss (1979), Table 2: six targets rated by four judges
SHROUT_FLEISS = np.array(
    [
        [9, 2, 5, 8],
        [6, 1, 3, 2],
        [8, 4, 6, 8],
        [7, 1, 2, 6],
        [10, 5, 6, 9],
        [6, 2, 4, 7],
    ],
    dtype=float,
)
# their Table 4: the six forms' values, to two decimals
SHROUT_FLEISS_ICC = {
    "ICC(1,1)": 0.17,
    "ICC(2,1)": 0.29,
    "ICC(3,1)": 0.71,
    "ICC(1,k)": 0.44,
    "ICC(2,k)": 0.62,
    "ICC(3,k)": 0.91,
}
PINGOUIN_TYPES = {  # pingouin 0.7's names: A = absolute agreement (two-way random), C = consistency
    "ICC(1,1)": "ICC(1,1)",
    "ICC(A,1)": "ICC(2,1)",
    "ICC(C,1)": "ICC(3,1)",
    "ICC(1,k)": "ICC(1,k)",
    "ICC(A,k)": "ICC(2,k)",
    "ICC(C,k)": "ICC(3,k)",
}

# Krippendorff (2011), "Computing Krippendorff's alpha-reliability", section C: 4 observers x 12 units
KRIPPENDORFF_2011 = np.array(
    [
        [1, 2, 3, 3, 2, 1, 4, 1, 2, np.nan, np.nan, np.nan],
        [1, 2, 3, 3, 2, 2, 4, 1, 2, 5, np.nan, 3],
        [np.nan, 3, 3, 3, 2, 3, 4, 2, 2, 5, 1, np.nan],
        [1, 2, 3, 3, 2, 4, 4, 1, 2, 5, 1, np.nan],
    ]
)


def pingouin_icc(matrix: np.ndarray) -> pd.DataFrame:
    n, k = matrix.shape
    long = pd.DataFrame(
        {
            "target": np.repeat(np.arange(n), k),
            "rater": np.tile(np.arange(k), n),
            "score": matrix.ravel(),
        }
    )
    with warnings.catch_warnings():  # pingouin's own use of deprecated pandas arguments
        warnings.simplefilter("ignore", DeprecationWarning)
        warnings.simplefilter("ignore", FutureWarning)
        warnings.simplefilter("ignore", pd.errors.Pandas4Warning)
        table = pingouin.intraclass_corr(long, targets="target", raters="rater", ratings="score")
    return table.set_index("Type")


def test_the_six_iccs_of_shrout_and_fleiss_worked_example():
    result = intraclass_correlation(SHROUT_FLEISS)
    for kind, published in SHROUT_FLEISS_ICC.items():
        assert result[kind].value == pytest.approx(published, abs=0.005), kind


def test_iccs_and_their_intervals_equal_pingouins():
    rng = np.random.default_rng(3)
    for matrix in (SHROUT_FLEISS, rng.normal(size=(12, 3)) + rng.normal(size=(12, 1)) * 2):
        ours, theirs = intraclass_correlation(matrix), pingouin_icc(matrix)
        for name, kind in PINGOUIN_TYPES.items():
            row = theirs.loc[name]
            assert ours[kind].value == pytest.approx(row["ICC"], abs=1e-12), kind
            assert ours[kind].f == pytest.approx(row["F"], rel=1e-9), kind
            assert ours[kind].p_value == pytest.approx(row["pval"], rel=1e-6, abs=1e-15), kind
            low, high = row["CI95"]  # pingouin rounds its interval to two decimals
            assert ours[kind].ci_low == pytest.approx(low, abs=0.005 + 1e-9), kind
            assert ours[kind].ci_high == pytest.approx(high, abs=0.005 + 1e-9), kind
            assert ours[kind].ci_low <= ours[kind].value <= ours[kind].ci_high, kind


@settings(max_examples=40, deadline=None)
@given(
    st.integers(3, 10),
    st.integers(2, 5),
    st.integers(0, 2**32 - 1),
    st.floats(0.1, 10.0),
    st.floats(-5.0, 5.0),
)
def test_icc_is_invariant_to_a_change_of_scale_and_absolute_agreement_punishes_a_biased_rater(
    n, k, seed, scale, shift
):
    rng = np.random.default_rng(seed)
    scores = rng.normal(size=(n, 1)) * 3 + rng.normal(size=(n, k))
    base = intraclass_correlation(scores)
    moved = intraclass_correlation(scores * scale + shift)
    for kind in base:
        assert moved[kind].value == pytest.approx(base[kind].value, abs=1e-9)
    if base["ICC(3,1)"].value <= 0:
        return  # raters agree less than chance: a shared offset then shrinks a negative ICC's size
    biased = scores.copy()
    biased[:, 0] += 10.0  # one rater scores everyone 10 points higher
    after = intraclass_correlation(biased)
    assert after["ICC(3,1)"].value == pytest.approx(base["ICC(3,1)"].value, abs=1e-9)  # consistency: same
    assert after["ICC(2,1)"].value < base["ICC(2,1)"].value  # agreement: worse


def test_an_icc_refuses_incomplete_or_too_small_tables():
    with pytest.raises(MetricsError, match="every target rated"):
        intraclass_correlation([[1, 2], [3, np.nan], [4, 5]])
    with pytest.raises(MetricsError, match="at least 2 targets and 2 raters"):
        intraclass_correlation([[1, 2, 3]])


def test_krippendorffs_worked_example_and_the_reference_package():
    nominal = krippendorff_alpha(KRIPPENDORFF_2011, "nominal", resamples=0)
    interval = krippendorff_alpha(KRIPPENDORFF_2011, "interval", resamples=0)
    assert nominal.value == pytest.approx(0.743, abs=0.0005)  # Krippendorff (2011), section C
    assert interval.value == pytest.approx(0.849, abs=0.0005)
    assert nominal.units == 11 and nominal.raters == 4  # unit 12 has one value: not pairable
    for level in ("nominal", "ordinal", "interval", "ratio"):
        ours = krippendorff_alpha(KRIPPENDORFF_2011, level, resamples=0).value
        theirs = krippendorff.alpha(reliability_data=KRIPPENDORFF_2011, level_of_measurement=level)
        assert ours == pytest.approx(theirs, abs=1e-12), level


@settings(max_examples=40, deadline=None)
@given(st.integers(2, 5), st.integers(3, 15), st.integers(0, 2**32 - 1))
def test_ordinal_alpha_equals_the_reference_package_on_random_rating_tables(raters, units, seed):
    rng = np.random.default_rng(seed)
    data = rng.integers(1, 6, size=(raters, units)).astype(float)
    data[rng.random(data.shape) < 0.2] = np.nan
    if (np.isfinite(data).sum(axis=0) >= 2).sum() < 1 or len(np.unique(data[np.isfinite(data)])) < 2:
        return  # nothing pairable, or one value used: alpha is undefined for both
    ours = krippendorff_alpha(data, "ordinal", resamples=0).value
    with np.errstate(invalid="ignore", divide="ignore"):  # the package divides 0 by 0 when undefined
        theirs = krippendorff.alpha(reliability_data=data, level_of_measurement="ordinal")
    if math.isnan(ours):
        assert math.isnan(theirs)
    else:
        assert ours == pytest.approx(theirs, abs=1e-9)


def test_alpha_is_one_for_perfect_agreement_and_its_interval_brackets_it():
    data = np.tile(np.array([1, 2, 3, 4, 5, 2, 3, 4.0]), (3, 1))
    perfect = krippendorff_alpha(data, "ordinal")
    assert perfect.value == 1.0 and perfect.band == "reliable"
    noisy = data.copy()
    noisy[0, :4] = [2, 1, 4, 3]
    result = krippendorff_alpha(noisy, "ordinal", resamples=500)
    assert result.ci_low <= result.value <= result.ci_high < 1.0 + 1e-12
    with pytest.raises(MetricsError, match="level"):
        krippendorff_alpha(data, "cardinal")


def test_cronbach_alpha_equals_pingouins():
    rng = np.random.default_rng(5)
    latent = rng.normal(size=(30, 1))
    items = latent + rng.normal(scale=0.8, size=(30, 5))
    ours = cronbach_alpha(items)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", pd.errors.Pandas4Warning)
        value, (low, high) = pingouin.cronbach_alpha(pd.DataFrame(items))
    assert ours.value == pytest.approx(value, abs=1e-12)
    assert ours.ci_low == pytest.approx(low, abs=0.0005 + 1e-9)  # pingouin rounds to three decimals
    assert ours.ci_high == pytest.approx(high, abs=0.0005 + 1e-9)


def test_the_largest_complete_block_drops_the_rater_who_rated_least():
    wide = pd.DataFrame(
        {
            "a": [1, 2, 3, 4, 5, 6],
            "b": [1, 2, 3, 4, 5, np.nan],
            "c": [1, np.nan, np.nan, 4, np.nan, np.nan],
        }
    )
    block = complete_block(wide)
    assert list(block.columns) == ["a", "b"] and len(block) == 5


def test_test_retest_takes_each_participants_last_sessions():
    rows = []
    rng = np.random.default_rng(1)
    for person in range(8):
        level = rng.normal() * 3
        for trial in range(1, 6):
            drift = 10.0 if trial <= 3 else 0.0  # learning: only the last two are at plateau
            rows.append(
                {"participant_id": f"p{person}", "trial": trial, "m": level + drift + rng.normal() * 0.1}
            )
    table = pd.DataFrame(rows)
    icc, used = test_retest(table, "m")
    assert used == 8 and icc.value > 0.95
    last_two = np.array(
        [g.sort_values("trial")["m"].to_numpy()[-2:] for _, g in table.groupby("participant_id")]
    )
    assert icc.value == pytest.approx(intraclass_correlation(last_two)["ICC(3,1)"].value, abs=1e-12)
    assert test_retest(table[table.participant_id.isin(["p0", "p1", "p2", "p3"])], "m") == (None, 4)
