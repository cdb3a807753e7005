"""Cross-checks against independent implementations where no published value exists."""
from __future__ import annotations

from itertools import combinations

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import optimize, stats

from results_analysis import (bradley_terry, conover, cronbach_alpha, fit_bradley_terry, friedman_ranks, holm,
                              kendall_w, nemenyi, pairwise_wins, rank_blocks, simulate_results, wilcoxon_holm,
                              within_block_ranks)
from results_analysis.descriptives import condition_summary
from results_analysis.errors import AnalysisInputError

rank_tables = st.integers(2, 6).flatmap(lambda k: st.lists(
    st.lists(st.integers(1, k), min_size=k, max_size=k), min_size=3, max_size=40))


@settings(max_examples=60, deadline=None)
@given(rank_tables)
def test_friedman_matches_scipy_with_ties(rows: list[list[int]]) -> None:
    values = np.array(rows, dtype=float)
    if values.shape[1] < 3 or np.all(values == values[:, :1]):
        return  # scipy needs k >= 3 and is undefined when every block ties completely
    ours = friedman_ranks(within_block_ranks(values))
    theirs = stats.friedmanchisquare(*values.T)
    assert ours.chi2 == pytest.approx(theirs.statistic, rel=1e-9, abs=1e-9)
    assert ours.p == pytest.approx(theirs.pvalue, rel=1e-9, abs=1e-12)


def _kendall_w_direct(ranks: np.ndarray) -> float:
    """Kendall & Babington Smith's W with tie correction, written from the textbook formula:
    W = 12 S / (m^2 (n^3 - n) - m sum T), S = sum (R_j - mean R)^2, T = sum over tie groups (t^3 - t),
    m raters (blocks), n objects (conditions)."""
    m, n = ranks.shape
    r = ranks.sum(axis=0)
    s = float(((r - r.mean()) ** 2).sum())
    t = 0.0
    for row in ranks:
        _, counts = np.unique(row, return_counts=True)
        t += float((counts ** 3 - counts).sum())
    return 12 * s / (m ** 2 * (n ** 3 - n) - m * t)


@settings(max_examples=60, deadline=None)
@given(rank_tables)
def test_kendall_w_matches_direct_formula(rows: list[list[int]]) -> None:
    ranks = within_block_ranks(np.array(rows, dtype=float))
    if np.all(ranks == ranks[:, :1]):
        return
    assert kendall_w(ranks) == pytest.approx(_kendall_w_direct(ranks), rel=1e-9, abs=1e-12)


def _holm_by_hand(p: list[float]) -> list[float]:
    """Holm (1979) step-down, written as a loop over the sorted p values."""
    m = len(p)
    order = sorted(range(m), key=lambda i: p[i])
    adjusted = [0.0] * m
    running = 0.0
    for step, i in enumerate(order):
        running = max(running, min(1.0, (m - step) * p[i]))
        adjusted[i] = running
    return adjusted


@settings(max_examples=100, deadline=None)
@given(st.lists(st.floats(0, 1), min_size=1, max_size=12))
def test_holm_matches_hand_written(p: list[float]) -> None:
    assert holm(p).tolist() == pytest.approx(_holm_by_hand(p))


def test_wilcoxon_holm_matches_scipy_and_hand_holm() -> None:
    rng = np.random.default_rng(4)
    values = within_block_ranks(rng.normal(size=(60, 4)) + np.array([0.0, 0.3, 0.5, 0.1]))
    values[:5, 1] = values[:5, 0]  # some zero differences
    names = list("ABCD")
    table = wilcoxon_holm(values, names)
    raw = []
    for (i, j), row in zip(combinations(range(4), 2), table.itertuples()):
        d = values[:, i] - values[:, j]
        # R's default for n >= 50 or ties: normal approximation with continuity correction, zeros dropped.
        ref = stats.wilcoxon(values[:, i], values[:, j], zero_method="wilcox", correction=True,
                             method="asymptotic")
        assert row.p == pytest.approx(ref.pvalue, rel=1e-12)
        assert row.statistic == pytest.approx(stats.rankdata(np.abs(d[d != 0]))[d[d != 0] > 0].sum())
        assert row.zeros_dropped == int((d == 0).sum())
        raw.append(ref.pvalue)
    assert table["p_adjusted"].tolist() == pytest.approx(_holm_by_hand(raw))
    assert (table["method"] == "normal approximation").all()


def test_conover_matches_formula_from_conover_1999() -> None:
    rng = np.random.default_rng(5)
    ranks = within_block_ranks(rng.integers(1, 4, size=(30, 3)).astype(float))
    b, k = ranks.shape
    r = ranks.sum(axis=0)
    a1 = (ranks ** 2).sum()
    denom = np.sqrt(2 * (b * a1 - (r ** 2).sum()) / ((b - 1) * (k - 1)))
    table = conover(ranks, ["A", "B", "C"])
    for (i, j), row in zip(combinations(range(3), 2), table.itertuples()):
        t = abs(r[i] - r[j]) / denom
        assert row.statistic == pytest.approx(t)
        assert row.p == pytest.approx(2 * stats.t.sf(t, (b - 1) * (k - 1)))


def test_nemenyi_p_matches_critical_difference() -> None:
    rng = np.random.default_rng(6)
    ranks = within_block_ranks(rng.normal(size=(40, 5)) + np.linspace(0, 1, 5))
    for alpha in (0.01, 0.05, 0.1):
        t = nemenyi(ranks, list("ABCDE"), alpha=alpha)
        # the single-step p falls below alpha exactly when the difference exceeds the CD
        assert ((t["p_adjusted"] < alpha) == t["significant"]).all()


def test_bradley_terry_mm_matches_scipy_optimize() -> None:
    rng = np.random.default_rng(7)
    ranks = within_block_ranks(rng.normal(size=(200, 4)) - np.array([0.8, 0.4, 0.0, 0.0]))
    ranks[:10] = within_block_ranks(np.array([[1, 1, 2, 3]] * 10, dtype=float))  # ties: half wins
    wins = pairwise_wins(ranks)
    # Independent fit: maximise sum_ij w_ij log(p_i / (p_i + p_j)) over log-strengths with scipy.
    def nll(theta):
        th = np.append(theta, 0.0)
        diff = th[:, None] - th[None, :]
        return -(wins * (diff - np.logaddexp(0, diff))).sum()
    opt = optimize.minimize(nll, np.zeros(3), method="BFGS", options={"gtol": 1e-10})
    theta = np.append(opt.x, 0.0)
    expected = np.exp(theta) / np.exp(theta).sum()
    assert fit_bradley_terry(wins, prior=0.0) == pytest.approx(expected, abs=1e-5)


def test_pairwise_wins_count_each_pair_once_per_block() -> None:
    ranks = within_block_ranks(np.random.default_rng(8).integers(1, 4, size=(25, 3)).astype(float))
    w = pairwise_wins(ranks)
    assert (w + w.T)[~np.eye(3, dtype=bool)] == pytest.approx(np.full(6, 25.0))


def test_bootstrap_intervals_are_seeded_and_cover_the_estimate() -> None:
    df = simulate_results(30, 6, seed=9, n_practice=0, n_attention=0)
    blocks = rank_blocks(df, "realism")
    a = condition_summary(blocks, n_boot=500, seed=3)
    b = condition_summary(blocks, n_boot=500, seed=3)
    c = condition_summary(blocks, n_boot=500, seed=4)
    pd.testing.assert_frame_equal(a, b)
    assert not np.allclose(a["ci_low"], c["ci_low"])
    assert ((a["ci_low"] <= a["mean_rank"]) & (a["mean_rank"] <= a["ci_high"])).all()
    bt = bradley_terry(blocks, n_boot=300, seed=1)
    assert ((bt["ci_low"] <= bt["strength"]) & (bt["strength"] <= bt["ci_high"])).all()
    assert bt["strength"].sum() == pytest.approx(1.0)


def test_bootstrap_resamples_participants_not_trials() -> None:
    # Participants who always agree with themselves but disagree with each other: a trial bootstrap would
    # give a narrow interval, the participant bootstrap a wide one (only 4 independent units).
    rows = []
    for p, order in enumerate([[1, 2, 3], [3, 2, 1], [1, 2, 3], [3, 2, 1]]):
        for t in range(50):
            rows += [{"participant": f"P{p}", "trial_index": t, "stimulus": f"s{t}", "criterion": "c",
                      "condition": c, "rank": r} for c, r in zip("ABC", order)]
    blocks = rank_blocks(pd.DataFrame(rows), "c")
    s = condition_summary(blocks, n_boot=2000, seed=0).set_index("condition")
    assert s.loc["A", "ci_high"] - s.loc["A", "ci_low"] > 1.0


def test_cronbach_alpha_matches_covariance_formula() -> None:
    rng = np.random.default_rng(10)
    latent = rng.normal(size=(80, 1))
    items = pd.DataFrame(latent + rng.normal(scale=0.8, size=(80, 5)), columns=list("abcde"))
    cov = np.cov(items.to_numpy(), rowvar=False)
    k = cov.shape[0]
    expected = k / (k - 1) * (1 - np.trace(cov) / cov.sum())
    assert cronbach_alpha(items) == pytest.approx(expected)
    # listwise deletion: a missing answer drops that participant only
    items.iloc[0, 2] = np.nan
    cov = np.cov(items.dropna().to_numpy(), rowvar=False)
    assert cronbach_alpha(items) == pytest.approx(k / (k - 1) * (1 - np.trace(cov) / cov.sum()))


def test_participant_block_uses_mean_rank_per_participant() -> None:
    df = simulate_results(10, 6, seed=11, n_practice=0, n_attention=0)
    blocks = rank_blocks(df, "diversity", block="participant")
    by_hand = (df[df.criterion == "diversity"].groupby(["participant", "condition"])["rank"].mean()
               .unstack()[blocks.conditions])
    assert blocks.values == pytest.approx(by_hand.to_numpy())
    assert friedman_ranks(blocks.ranks).chi2 == pytest.approx(stats.friedmanchisquare(*by_hand.to_numpy().T).statistic)


@settings(max_examples=40, deadline=None)
@given(st.integers(3, 5), st.integers(3, 25), st.integers(0, 10_000))
def test_skillings_mack_without_missing_is_friedman_uncorrected(k: int, n: int, seed: int) -> None:
    from results_analysis.skillings_mack import skillings_mack

    values = np.random.default_rng(seed).normal(size=(n, k))  # continuous: no ties
    sm = skillings_mack(values)
    assert sm.statistic == pytest.approx(friedman_ranks(within_block_ranks(values), tie_correction=False).chi2,
                                         rel=1e-9, abs=1e-9)
    assert sm.n_missing == 0 and sm.df == k - 1


def test_skillings_mack_on_a_balanced_incomplete_design_is_durbin() -> None:
    """For a BIBD, Skillings-Mack reduces to Durbin's test: D = 12(t-1)/(r t (k-1)(k+1)) sum R_j^2
    - 3 r (t-1)(k+1)/(k-1) with t treatments, blocks of size k, each treatment r times."""
    from itertools import combinations as comb

    from results_analysis.skillings_mack import skillings_mack

    rng = np.random.default_rng(12)
    t, k = 5, 3
    design = list(comb(range(t), k)) * 2
    values = np.full((len(design), t), np.nan)
    for i, b in enumerate(design):
        values[i, list(b)] = rng.normal(size=k) + 0.4 * np.array(b)
    r = len(design) * k // t
    rank_sums = np.zeros(t)
    for i, b in enumerate(design):
        rank_sums[list(b)] += stats.rankdata(values[i, list(b)])
    durbin = 12 * (t - 1) / (r * t * (k - 1) * (k + 1)) * (rank_sums ** 2).sum() - 3 * r * (t - 1) * (k + 1) / (k - 1)
    res = skillings_mack(values)
    assert res.statistic == pytest.approx(durbin)
    assert res.p == pytest.approx(stats.chi2.sf(durbin, t - 1))


def test_skillings_mack_permutation_p_matches_full_enumeration() -> None:
    """The Monte Carlo p-value against the exact permutation distribution, enumerated by brute force over every
    within-block arrangement of a small incomplete data set (3! * 3! * 2! * 2! * 3! = 864 arrangements)."""
    from itertools import permutations, product

    from results_analysis.skillings_mack import skillings_mack

    values = np.array([[1.0, 2, 3], [2, 1, 3], [1, np.nan, 2], [np.nan, 1, 2], [1, 3, 2]])
    observed = skillings_mack(values).statistic
    per_block = []
    for row in values:
        cells = np.flatnonzero(~np.isnan(row))
        per_block.append([(cells, row[cells][list(p)]) for p in permutations(range(len(cells)))])
    extreme = total = 0
    for arrangement in product(*per_block):
        v = np.full(values.shape, np.nan)
        for i, (cells, vals) in enumerate(arrangement):
            v[i, cells] = vals
        total += 1
        extreme += skillings_mack(v).statistic >= observed - 1e-9
    exact = extreme / total
    assert total == 864
    mc = skillings_mack(values, n_perm=40_000, seed=3)
    assert mc.n_permutations == 40_000
    assert mc.p_permutation == pytest.approx(exact, abs=4 * np.sqrt(exact * (1 - exact) / 40_000) + 1e-4)
    assert skillings_mack(values, n_perm=500, seed=9).p_permutation == skillings_mack(values, n_perm=500, seed=9).p_permutation


def test_skillings_mack_permutation_p_agrees_with_chi2_on_many_blocks() -> None:
    """With many blocks the chi-squared approximation is good, so the two p-values must be close."""
    from results_analysis.skillings_mack import skillings_mack

    rng = np.random.default_rng(5)
    values = rng.normal(size=(300, 3)) + np.array([0.0, 0.1, 0.2])
    values[rng.random(values.shape) < 0.1] = np.nan
    res = skillings_mack(values, n_perm=4000, seed=1)
    assert 0.01 < res.p < 0.99
    assert res.p_permutation == pytest.approx(res.p, abs=0.03)


def test_wilcoxon_follows_r_on_zeros_and_the_exact_limit(r_wilcox_normal_p) -> None:
    """R's wilcox.test uses the exact distribution only for n < 50 non-zero differences with neither ties nor
    zeros; scipy's 'auto' would stay exact after dropping zeros. The p values must be R's in every branch."""
    d = np.arange(1.0, 21.0)  # 20 distinct |d|, no zeros; three negatives: V = 210 - (2 + 5 + 11) = 192
    d[[1, 4, 10]] *= -1
    zeros = np.r_[d, 0.0, 0.0]
    row = wilcoxon_holm(np.c_[zeros, np.zeros_like(zeros)], ["a", "b"]).iloc[0]
    v, p = r_wilcox_normal_p(zeros)
    assert row.zeros_dropped == 2 and row.method == "normal approximation" and row.continuity_correction
    assert row.statistic == v and row.p == pytest.approx(p, rel=1e-12)
    # without the zeros the same differences get the exact test (scipy's exact = R's psignrank)
    exact = wilcoxon_holm(np.c_[d, np.zeros_like(d)], ["a", "b"]).iloc[0]
    assert exact.method == "exact" and exact.p == pytest.approx(stats.wilcoxon(d, method="exact").pvalue)
    assert exact.p != pytest.approx(p, rel=1e-6)
    for n, method in ((49, "exact"), (50, "normal approximation")):
        dn = np.arange(1, n + 1) * np.where(np.arange(n) % 3 == 0, -1.0, 1.0)
        r = wilcoxon_holm(np.c_[dn, np.zeros(n)], ["a", "b"]).iloc[0]
        assert r.method == method, n
        if method != "exact":
            assert r.p == pytest.approx(r_wilcox_normal_p(dn)[1], rel=1e-12)


def test_dataframe_api_gives_the_numbers_of_the_full_analysis() -> None:
    """Notebook use: tidy or wide DataFrames in, DataFrames out, equal to what the command-line analysis
    computes (practice and attention-check trials left out the same way)."""
    from results_analysis import run_analysis

    df = simulate_results(12, 4, seed=14)
    full = run_analysis(df, block="trial", n_boot=300, seed=2).criteria["synchronization"]
    pd.testing.assert_frame_equal(condition_summary(df, "synchronization", n_boot=300, seed=2), full.summary)
    pd.testing.assert_frame_equal(bradley_terry(df, "synchronization", n_boot=150, seed=2), full.bradley_terry)
    rated = df[~df.is_practice & ~df.is_attention_check & (df.criterion == "synchronization")]
    wide = rated.pivot(index=["participant", "trial_index"], columns="condition", values="rank")
    assert list(wide.columns) == full.blocks.conditions
    for table, ref in ((nemenyi(wide), full.posthoc["nemenyi"]), (wilcoxon_holm(wide), full.posthoc["wilcoxon_holm"])):
        pd.testing.assert_frame_equal(table.reset_index(drop=True), ref.reset_index(drop=True))
    assert conover(wide)["p"].tolist() == pytest.approx(conover(full.blocks.ranks, full.blocks.conditions)["p"].tolist())
    with pytest.raises(ValueError, match="criteria"):
        condition_summary(df)
    # conditions given with a wide frame pick its columns by name, whatever their order in the frame
    shuffled = wide[list(reversed(wide.columns))]
    pd.testing.assert_frame_equal(nemenyi(shuffled, list(wide.columns)).reset_index(drop=True),
                                  full.posthoc["nemenyi"].reset_index(drop=True))
    with pytest.raises(KeyError, match="not columns"):
        nemenyi(wide, ["nope", *wide.columns[1:]])
    # flags exported as text read as the command line reads them; nothing rated is an error, not an empty table
    texty = df.assign(is_practice=df.is_practice.map({True: "yes", False: "no"}),
                      is_attention_check=df.is_attention_check.map({True: "yes", False: "no"}))
    pd.testing.assert_frame_equal(condition_summary(texty, "synchronization", n_boot=300, seed=2), full.summary)
    with pytest.raises(AnalysisInputError, match="no rated trials"):
        condition_summary(df.assign(is_practice=True), "synchronization")
