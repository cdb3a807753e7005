"""The statistics reproduce values published by R, scipy, pingouin, Demsar (2006) and R's wilcox.test docs.

Every expected number here is copied from the publication named next to it, never from our own output.
"""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from results_analysis import (critical_difference, friedman, friedman_ranks, nemenyi, nemenyi_q_alpha,
                              wilcoxon_holm, within_block_ranks)

# R, ?friedman.test: "Comparison of three methods ('round out', 'narrow angle', and 'wide angle') for rounding
# first base" (Hollander & Wolfe 1973, p. 140ff). R prints: Friedman chi-squared = 11.143, df = 2,
# p-value = 0.003805.
ROUNDING_TIMES = np.array([
    [5.40, 5.50, 5.55], [5.85, 5.70, 5.75], [5.20, 5.60, 5.50], [5.55, 5.50, 5.40], [5.90, 5.85, 5.70],
    [5.45, 5.55, 5.60], [5.40, 5.40, 5.35], [5.45, 5.50, 5.35], [5.25, 5.15, 5.00], [5.85, 5.80, 5.70],
    [5.25, 5.20, 5.10], [5.65, 5.55, 5.45], [5.60, 5.35, 5.45], [5.05, 5.00, 4.95], [5.50, 5.50, 5.40],
    [5.45, 5.55, 5.50], [5.55, 5.55, 5.35], [5.45, 5.50, 5.55], [5.50, 5.45, 5.25], [5.65, 5.60, 5.40],
    [5.70, 5.65, 5.55], [6.30, 6.30, 6.25]])


def test_r_friedman_rounding_times() -> None:
    wide = pd.DataFrame(ROUNDING_TIMES, columns=["Round Out", "Narrow Angle", "Wide Angle"])
    res = friedman(wide).iloc[0]
    assert res["chi2"] == pytest.approx(11.143, abs=5e-4)
    assert res["df"] == 2
    assert res["p"] == pytest.approx(0.003805, abs=5e-7)
    # The data has ties (e.g. 5.40, 5.40, 5.35): without the correction the statistic is smaller.
    raw = friedman(wide, tie_correction=False).iloc[0]
    assert raw["chi2"] < res["chi2"] - 0.3


def test_r_friedman_rounding_times_long_format() -> None:
    long = pd.DataFrame(ROUNDING_TIMES, columns=["round", "narrow", "wide"]).rename_axis("player").reset_index()
    long = long.melt(id_vars="player", var_name="method", value_name="time")
    res = friedman(long, dv="time", within="method", subject="player").iloc[0]
    assert res["chi2"] == pytest.approx(11.143, abs=5e-4)
    assert res["p"] == pytest.approx(0.003805, abs=5e-7)


def test_scipy_friedmanchisquare_documented_example() -> None:
    # SciPy's hypothesis-test tutorial for friedmanchisquare: pulse rate of seven students before, immediately
    # after and 5 minutes after exercise; res.statistic = 10.57142857142857, res.pvalue = 0.005063414171757498.
    # (No ties: rank sums 10, 21, 11, so chi2 = 12/84 * 662 - 84 = 74/7 by hand as well.)
    wide = pd.DataFrame({"before": [72, 96, 88, 92, 74, 76, 82],
                         "immediately_after": [120, 120, 132, 120, 101, 96, 112],
                         "five_min_after": [76, 95, 104, 96, 84, 72, 76]})
    res = friedman(wide).iloc[0]
    assert res["chi2"] == pytest.approx(10.57142857142857, rel=1e-12)
    assert res["p"] == pytest.approx(0.005063414171757498, rel=1e-9)


def test_scipy_friedmanchisquare_docstring_example() -> None:
    # scipy.stats.friedmanchisquare docstring (SciPy 1.17): x = default_rng(seed=18).random((6, 10)), six
    # conditions x ten blocks -> (11.428571428571416, 0.043514520866727614).
    x = np.random.default_rng(seed=18).random((6, 10))
    res = friedman(pd.DataFrame(x.T)).iloc[0]
    assert res["chi2"] == pytest.approx(11.428571428571416, rel=1e-12)
    assert res["p"] == pytest.approx(0.043514520866727614, rel=1e-9)
    assert (res["n_blocks"], res["k"], res["df"]) == (10, 6, 5)


def test_pingouin_friedman_wine_example() -> None:
    # pingouin.friedman docstring (pingouin 0.7.0; also its test suite, checked there against R's
    # friedman.test and DescTools::KendallW): 12 raters x 3 wines, W = 0.083333, Q = 2.0, p_unc = 0.367879.
    wide = pd.DataFrame({
        "white": [10, 8, 7, 9, 7, 4, 5, 6, 5, 10, 4, 7],
        "red": [7, 5, 8, 6, 5, 7, 9, 6, 4, 6, 7, 3],
        "rose": [8, 5, 6, 4, 7, 5, 3, 7, 6, 4, 4, 3]})
    res = friedman(wide).iloc[0]
    assert res["chi2"] == pytest.approx(2.0, abs=1e-9)
    assert res["p"] == pytest.approx(0.3678794, abs=1e-7)
    assert res["kendall_w"] == pytest.approx(0.08333333, abs=1e-8)
    long = wide.rename_axis("rater").reset_index().melt(id_vars="rater", var_name="wine", value_name="score")
    assert friedman(long, dv="score", within="wine", subject="rater").iloc[0]["chi2"] == pytest.approx(2.0)


# Demsar (2006), "Statistical comparisons of classifiers over multiple data sets", JMLR 7, Table 6: AUC of
# C4.5, C4.5+m, C4.5+cf, C4.5+m+cf on 14 data sets. The printed table rounds to 3 decimals, which ties
# C4.5+cf and C4.5+m+cf on 'voting' (0.975); the paper's ranks (2.893 / 1.964) show C4.5+cf was the
# higher, so that cell is 0.97501 here (as in public re-implementations of the example).
DEMSAR_AUC = np.array([
    [0.763, 0.768, 0.771, 0.798], [0.599, 0.591, 0.590, 0.569], [0.954, 0.971, 0.968, 0.967],
    [0.628, 0.661, 0.654, 0.657], [0.882, 0.888, 0.886, 0.898], [0.936, 0.931, 0.916, 0.931],
    [0.661, 0.668, 0.609, 0.685], [0.583, 0.583, 0.563, 0.625], [0.775, 0.838, 0.866, 0.875],
    [1.000, 1.000, 1.000, 1.000], [0.940, 0.962, 0.965, 0.962], [0.619, 0.666, 0.614, 0.669],
    [0.972, 0.981, 0.97501, 0.975], [0.957, 0.978, 0.946, 0.970]])
DEMSAR_NAMES = ["C4.5", "C4.5+m", "C4.5+cf", "C4.5+m+cf"]


def test_demsar_mean_ranks_statistics_and_cd() -> None:
    ranks = within_block_ranks(-DEMSAR_AUC)  # higher AUC is better: rank 1 to the largest
    res_uncorrected = friedman_ranks(ranks, tie_correction=False)
    # "average ranks 3.143, 2.000, 2.893 and 1.964"; chi2_F = 9.28; F_F = 3.69 (Demsar's printed example
    # does not correct for ties).
    assert np.round(res_uncorrected.mean_rank, 3).tolist() == [3.143, 2.000, 2.893, 1.964]
    assert res_uncorrected.chi2 == pytest.approx(9.28, abs=5e-3)
    assert res_uncorrected.iman_davenport_f == pytest.approx(3.69, abs=5e-3)
    assert (res_uncorrected.iman_davenport_df1, res_uncorrected.iman_davenport_df2) == (3, 39)
    # "CD = 2.569 sqrt(4*5/(6*14)) = 1.25" at alpha = 0.05 and 1.12 at alpha = 0.10 (q = 2.291).
    assert critical_difference(4, 14, 0.05) == pytest.approx(1.25, abs=5e-3)
    assert critical_difference(4, 14, 0.10) == pytest.approx(1.12, abs=5e-3)
    # "the data is not sufficient to reach any conclusion" at 0.05; at 0.10 C4.5 is worse than C4.5+m
    # and C4.5+m+cf, and C4.5+cf cannot be placed.
    strict = nemenyi(ranks, DEMSAR_NAMES, alpha=0.05)
    assert not strict["significant"].any()
    loose = nemenyi(ranks, DEMSAR_NAMES, alpha=0.10)
    assert {(r.a, r.b) for r in loose.itertuples() if r.significant} == {("C4.5", "C4.5+m"), ("C4.5", "C4.5+m+cf")}
    assert ((loose["p_adjusted"] < 0.10) == loose["significant"]).all()


@pytest.mark.parametrize("k, q05, q10", [(2, 1.960, 1.645), (3, 2.343, 2.052), (4, 2.569, 2.291), (5, 2.728, 2.459),
                                         (6, 2.850, 2.589), (7, 2.949, 2.693), (8, 3.031, 2.780),
                                         (9, 3.102, 2.855), (10, 3.164, 2.920)])
def test_demsar_table5_critical_values(k: int, q05: float, q10: float) -> None:
    # Demsar (2006) Table 5(a)/(b): critical values of the two-tailed Nemenyi test (3 decimals).
    assert nemenyi_q_alpha(k, 0.05) == pytest.approx(q05, abs=1.5e-3)
    assert nemenyi_q_alpha(k, 0.10) == pytest.approx(q10, abs=1.5e-3)


def test_r_wilcox_test_paired_example() -> None:
    # R ?wilcox.test (Hollander & Wolfe 1973, p. 29f): depression scale at first (x) and second (y) visit;
    # wilcox.test(x, y, paired = TRUE, alternative = "greater") gives V = 40, p-value = 0.01953, so the
    # two-sided exact p is 2 * 0.01953.
    x = [1.83, 0.50, 1.62, 2.48, 1.68, 1.88, 1.55, 3.06, 1.30]
    y = [0.878, 0.647, 0.598, 2.05, 1.06, 1.29, 1.06, 3.14, 1.29]
    row = wilcoxon_holm(np.c_[x, y], ["first", "second"]).iloc[0]
    assert row["statistic"] == 40
    assert row["method"] == "exact" and not row["continuity_correction"]
    assert row["p"] == pytest.approx(2 * 0.01953, abs=1e-5)
    assert row["p_adjusted"] == row["p"]  # one pair: Holm changes nothing


def test_r_wilcox_test_normal_approximation_example(r_wilcox_normal_p) -> None:
    # R ?wilcox.test, same data: wilcox.test(y - x, alternative = "less", exact = FALSE, correct = FALSE)
    # ("H&W large sample approximation") gives V = 5, p-value = 0.01908. Our hand-written copy of R's
    # normal approximation (conftest.py; it checks the continuity-corrected variant in test_crosscheck) must
    # agree.
    x = np.array([1.83, 0.50, 1.62, 2.48, 1.68, 1.88, 1.55, 3.06, 1.30])
    y = np.array([0.878, 0.647, 0.598, 2.05, 1.06, 1.29, 1.06, 3.14, 1.29])
    v, p_two_sided = r_wilcox_normal_p(y - x, correct=False)
    assert v == 5
    assert p_two_sided / 2 == pytest.approx(0.01908, abs=5e-6)


def test_scipy_wilcoxon_documented_example() -> None:
    # scipy.stats.wilcoxon docstring: Darwin's cross- minus self-fertilized corn heights,
    # d = [6, 8, ..., 75]; two-sided exact p = 0.041259765625, and alternative='greater' reports the sum of
    # the ranks of the positive differences, 96.0 (what R calls V).
    d = np.array([6, 8, 14, 16, 23, 24, 28, 29, 41, -48, 49, 56, 60, -67, 75], dtype=float)
    row = wilcoxon_holm(np.c_[d, np.zeros_like(d)], ["cross", "self"]).iloc[0]
    assert row["method"] == "exact"
    assert row["statistic"] == 96
    assert row["p"] == pytest.approx(0.041259765625, rel=1e-12)


def test_pingouin_cronbach_alpha_listwise_example() -> None:
    # pingouin.cronbach_alpha docstring (pingouin 0.7.0), data set 'cronbach_wide_missing' (binary answers of
    # 12 people to 11 items, from real-statistics.com): after listwise deletion, "In R:
    # psych:alpha(data, use='complete.obs')" alpha = 0.8016949152542373.
    from results_analysis import cronbach_alpha

    nan = np.nan
    data = pd.DataFrame([
        [1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1], [1, 1, 1, 1, 1, 1, 1, 1, 0, 1, 0], [nan, 0, 1, 1, nan, 1, 1, 1, 1, 0, 0],
        [1, 1, 1, 0, 1, 1, 0, 1, 1, 0, 0], [1, 1, 1, 1, 1, 0, 0, 0, 1, 0, 0], [0, 1, nan, 0, 1, 1, 1, 1, 0, 0, 0],
        [1, 1, 1, 1, 0, 0, 1, 0, 0, 0, 0], [1, 1, 1, 1, 1, 0, 0, 0, 0, 0, 0], [0, 1, 0, 1, 1, 0, 0, 0, 0, 1, 0],
        [1, 0, 0, 1, 0, 1, 0, 0, nan, 0, 0], [1, 1, 1, 0, 0, 0, 0, 0, 0, 0, 0], [1, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0]],
        columns=[f"Q{i}" for i in range(1, 12)])
    assert cronbach_alpha(data) == pytest.approx(0.8016949152542373, rel=1e-12)
