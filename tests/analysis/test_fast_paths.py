"""The fast paths of the large-study analysis give the numbers of the general computations they replace.

Each fast path (issue #20: 10,000 participants within 5 s) is compared, on generated data with ties, gaps and
duplicates, with the plain numpy / scipy / pandas computation it stands in for: within-row ranks with
``scipy.stats.rankdata``, tie sizes with ``np.isclose`` over the (n, k, k) cube, trial rows with ``np.unique``,
group sizes with pandas' ``groupby().transform("size")``, the trials x conditions matrix with
``pivot_table``, the resample weights with one ``np.bincount`` of the whole draw, the rank rows and breakdown
levels with the pandas expressions they replaced. Exact equality throughout: the analysis must print the same
numbers.
"""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from scipy.stats import rankdata

from results_analysis.bootstrap import resample_weights
from results_analysis.errors import AnalysisInputError
from results_analysis.paradigms import other_rows, paradigm_of, rank_rows
from results_analysis.ranks import _row_ranks, _sorted_distinct, rank_blocks, text_levels, tie_sizes, ties
from results_analysis.study_meta import condition_labels, condition_order
from results_analysis.validate import _codes, _sizes, design_hashes, distinct_rows


def _ranks_with_ties(rng: np.random.Generator, n: int, k: int, step: float) -> np.ndarray:
    return rng.integers(0, k, (n, k)).astype(float) * step


@pytest.mark.parametrize("k", [2, 3, 4, 6, 7, 9])
@pytest.mark.parametrize("step", [0.5, 1 / 3, 1e-9])
def test_row_ranks_equal_rankdata(k, step):
    x = _ranks_with_ties(np.random.default_rng(k), 5000, k, step)
    got = _row_ranks(x)
    assert got.dtype == np.float64
    assert np.array_equal(got, rankdata(x, axis=1, method="average"))


def test_row_ranks_with_missing_values_go_to_rankdata():
    x = _ranks_with_ties(np.random.default_rng(1), 200, 3, 0.5)
    x[5, 1] = np.nan
    assert np.array_equal(_row_ranks(x), rankdata(x, axis=1, method="average"), equal_nan=True)


@pytest.mark.parametrize("k", [2, 3, 5, 8])
@pytest.mark.parametrize("step", [0.5, 1 / 3, 1e-9])
def test_tie_sizes_equal_isclose_cube(k, step):
    r = _ranks_with_ties(np.random.default_rng(10 + k), 4000, k, step)
    want = np.isclose(r[:, :, None], r[:, None, :]).sum(axis=2)
    got = tie_sizes(r)
    assert got.dtype == want.dtype and np.array_equal(got, want)
    assert np.array_equal(ties(r[:, :, None], r[:, None, :]), np.isclose(r[:, :, None], r[:, None, :]))


@pytest.mark.parametrize("n,span", [(0, 7), (1, 1), (50, 20), (100_000, 150_000), (1000, 10 ** 12)])
def test_sorted_distinct_equals_unique(n, span):
    codes = np.random.default_rng(n).integers(0, span, n)
    want = np.unique(codes, return_inverse=True)
    got = _sorted_distinct(codes, span)
    for a, b in zip(got, want):
        assert a.dtype == b.dtype and np.array_equal(a, b)


def _tidy(rng: np.random.Generator, n_part: int = 300) -> pd.DataFrame:
    rows = []
    for p in range(n_part):
        for t in range(rng.integers(1, 5)):
            for crit in ("realism", "sync"):
                for cond in rng.permutation(["A", "B", "C"])[: rng.integers(2, 4)]:  # some trials incomplete
                    rows.append({"participant": f"P{rng.integers(0, n_part):04d}", "trial_index": float(t),
                                 "criterion": crit, "condition": cond, "rank": float(rng.integers(1, 4)),
                                 "stimulus": f"s{rng.integers(0, 4)}"})
    return pd.DataFrame(rows)  # participants drawn at random: duplicated answers and unsorted rows too


def test_group_sizes_equal_groupby_size():
    df = _tidy(np.random.default_rng(3))
    for cols in (["participant", "trial_index", "criterion", "condition"], ["participant", "trial_index"]):
        codes = _codes(df, cols)
        assert np.array_equal(_sizes(codes), df.groupby(cols, sort=False)["rank"].transform("size").to_numpy())


def test_sizes_of_a_wide_key_space_are_hashed_not_counted():
    # four columns of 5,000 distinct values each: 6e14 possible keys, counted by hashing the 5,000 present
    df = pd.DataFrame({c: np.arange(5000) for c in "abcd"})
    df.loc[7] = df.loc[3]
    codes = _codes(df, list("abcd"))
    assert np.array_equal(_sizes(codes), df.groupby(list("abcd"))["a"].transform("size").to_numpy())


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_trial_matrix_equals_pivot_table(seed):
    df = _tidy(np.random.default_rng(seed))
    want = (df[df["criterion"] == "realism"]
            .pivot_table(index=["participant", "trial_index"], columns="condition", values="rank", aggfunc="first")
            .reindex(columns=["A", "B", "C"]))
    b = rank_blocks(df, "realism", block="trial", conditions=["A", "B", "C"], complete_only=False)
    assert np.array_equal(b.participants, want.index.get_level_values(0).to_numpy(dtype=object))
    assert np.array_equal(b.values, rankdata(np.where(np.isnan(want.to_numpy()), np.inf, want.to_numpy()), axis=1)
                          * np.where(np.isnan(want.to_numpy()), np.nan, 1.0), equal_nan=True)


def test_trial_matrix_takes_the_first_of_duplicated_answers():
    df = pd.DataFrame({"participant": "P1", "trial_index": 0.0, "criterion": "c",
                       "condition": ["A", "B", "A", "C"], "rank": [1.0, 2.0, 3.0, 3.0]})
    assert rank_blocks(df, "c", block="trial", conditions=["A", "B", "C"]).values.tolist() == [[1.0, 2.0, 3.0]]


@pytest.mark.parametrize("clusters,n_boot", [(7, 50), (3000, 120), (300_000, 3)])
def test_resample_weights_equal_counts_of_the_draw(clusters, n_boot):
    idx = np.random.default_rng(5).integers(0, clusters, (n_boot, clusters))
    want = np.stack([np.bincount(row, minlength=clusters) for row in idx]).astype(float)
    assert np.array_equal(resample_weights(clusters, n_boot, 5), want)


def test_rank_rows_equal_paradigm_rule():
    values = ["rank", None, "", "pairwise", np.nan, "rating", "rank", "mismatch"]
    for col in (pd.Series(values, dtype=object), pd.array(["rank", pd.NA, "", "rating"], dtype="string"),
                pd.Series(["rank"] * 5, dtype=object)):
        df = pd.DataFrame({"paradigm": col, "i": range(len(col))})
        is_rank = (paradigm_of(df) == "rank").to_numpy()
        assert rank_rows(df)["i"].tolist() == df["i"][is_rank].tolist()
        assert other_rows(df)["i"].tolist() == df["i"][~is_rank].tolist()


@pytest.mark.parametrize("values", [["b", None, "a", "b", np.nan], ["x", "y", "x"], [1, None, 2.5, "1"],
                                    [True, False, None]])
def test_text_levels_equal_categorical_of_text(values):
    col = pd.Series(values, dtype=object)
    want = pd.Categorical(col.fillna("(none)").astype(str).to_numpy(dtype=object))
    got = text_levels(col, "(none)")
    assert list(got.categories) == list(want.categories) and np.array_equal(got.codes, want.codes)
    full = col.dropna()
    want = pd.Categorical(full.astype(str).to_numpy(dtype=object))
    got = text_levels(full)
    assert list(got.categories) == list(want.categories) and np.array_equal(got.codes, want.codes)


def test_design_hashes_equal_sorted_unique():
    df = pd.DataFrame({"design_hash": ["b", None, "a", np.nan, "b", "c"]})
    assert design_hashes(df) == sorted(df["design_hash"].dropna().unique()) == ["a", "b", "c"]
    assert design_hashes(pd.DataFrame({"x": [1]})) == []


def test_distinct_rows_equal_drop_duplicates():
    df = _tidy(np.random.default_rng(4))
    for cols in (["participant", "trial_index"], ["participant", "trial_index", "criterion", "condition"]):
        assert distinct_rows(df, cols) == df[cols].drop_duplicates().shape[0]
    wide = pd.DataFrame({c: np.arange(5000) for c in "abcd"})
    wide.loc[7] = wide.loc[3]
    assert distinct_rows(wide, list("abcd")) == 4999
    gaps = pd.DataFrame({"p": ["a", None, None, "b"], "t": [0.0, 1.0, 1.0, np.nan]})
    assert distinct_rows(gaps, ["p", "t"]) == gaps.drop_duplicates().shape[0] == 3
    assert distinct_rows(df.iloc[:0], ["participant", "trial_index"]) == 0


def _order_and_labels_row_by_row(df: pd.DataFrame) -> tuple[list[str], dict[str, str]]:
    """condition_order and condition_labels as they walked every row before (the reference)."""
    ids = sorted(df["condition"].astype(str).unique())
    pos = pd.to_numeric(df["condition_position"], errors="coerce")
    place, owner = {}, {}
    for cid, p, w in zip(df["condition"].astype(str), pos, df["_where"]):
        if pd.isna(p):
            continue
        if place.setdefault(cid, p) != p:
            raise AnalysisInputError(None, f"{w}, column 'condition_position'", f"{cid} two positions")
        if owner.setdefault(p, cid) != cid:
            raise AnalysisInputError(None, f"{w}, column 'condition_position'", f"{p} two conditions")
    order = sorted(ids, key=lambda c: (c not in place, place.get(c, 0.0), c))
    found = {}
    for cid, label, w in zip(df["condition"].astype(str), df["condition_label"], df["_where"]):
        if label is None or (isinstance(label, float) and np.isnan(label)) or not str(label).strip():
            continue
        label = " ".join(str(label).split())
        if found.setdefault(cid, label) != label:
            raise AnalysisInputError(None, f"{w}, column 'condition_label'", f"{cid} two labels")
    return order, {c: found.get(c, c) for c in order}


@pytest.mark.parametrize("seed", range(12))
def test_condition_order_and_labels_equal_the_row_by_row_walk(seed):
    rng = np.random.default_rng(seed)
    n = 4000
    cond = rng.choice(["A", "B", "C"], n)
    position = pd.Series({"A": 2.0, "B": 0.0, "C": 1.0}).reindex(cond).to_numpy(copy=True)
    label = pd.Series({"A": "Alpha", "B": "Beta  model", "C": None}).reindex(cond).to_numpy(dtype=object, copy=True)
    position[rng.random(n) < 0.2] = np.nan  # rows without a position or label
    label[rng.random(n) < 0.2] = rng.choice([None, np.nan, "", "  "])
    if seed % 3 == 1:  # a conflict somewhere: the same row must be named
        i = int(rng.integers(100, n))
        position[i] = 5.0 if seed % 2 else {"A": 0.0, "B": 1.0, "C": 2.0}[cond[i]]
    if seed % 3 == 2:
        label[int(rng.integers(100, n))] = pd.NA if seed % 2 else "Gamma"
    df = pd.DataFrame({"condition": cond, "condition_position": position,
                       "condition_label": pd.Series(label, dtype=object),  # as read: None, NaN, pd.NA kept apart
                       "_where": [f"line {i + 2}" for i in range(n)]})
    try:
        want = _order_and_labels_row_by_row(df)
    except AnalysisInputError as exc:
        with pytest.raises(AnalysisInputError) as got:
            order = condition_order(df)
            condition_labels(df, order)
        assert str(got.value).split(",")[0] == str(exc).split(",")[0]  # the same row named first
        return
    order = condition_order(df)
    assert (order, condition_labels(df, order)) == want


def _z_by_ranking_every_difference(x: np.ndarray, shift: float) -> float:
    """R's wdiff, written out on every difference (the computation the distinct-value one replaces)."""
    xd = np.round(x - shift, 10)
    xd = xd[xd != 0]
    n = xd.size
    if n == 0:
        return 0.0
    r = rankdata(np.abs(xd))
    z = r[xd > 0].sum() - n * (n + 1) / 4.0
    _, t = np.unique(r, return_counts=True)
    sigma = np.sqrt(n * (n + 1) * (2 * n + 1) / 24.0 - np.sum(t ** 3 - t) / 48.0)
    return float((z - np.sign(z) * 0.5) / sigma) if sigma > 0 else 0.0


@pytest.mark.parametrize("seed", range(6))
def test_signed_rank_z_from_distinct_values_equals_ranking_every_difference(seed):
    from results_analysis.effect_sizes import _z_shifted, walsh_distinct
    rng = np.random.default_rng(seed)
    # participants' mean-rank differences: multiples of 1/16 (or thirds), many ties, some zeros
    step = 1 / 16 if seed % 2 else 1 / 3
    x = rng.integers(-32, 33, rng.integers(1, 3000)) * step
    values, counts = np.unique(x, return_counts=True)
    walsh = walsh_distinct(x)[0]
    shifts = np.r_[walsh, (walsh[:-1] + walsh[1:]) / 2.0, walsh[0] - 1.0, walsh[-1] + 1.0, 0.0]
    for shift in rng.choice(shifts, min(60, shifts.size), replace=False):
        assert _z_shifted(values, counts, shift) == _z_by_ranking_every_difference(x, shift)


def test_resample_counts_are_the_float64_weights_in_float32():
    from results_analysis.bootstrap import resample_counts
    counts = resample_counts(3001, 40, 9)
    assert counts.dtype == np.float32 and np.array_equal(counts.astype(np.float64), resample_weights(3001, 40, 9))


@pytest.mark.parametrize("step, total_scale", [(0.5, 1), (1 / 16, 1), (1.0, 1), (1 / 3, 1), (0.5, 4001), (0.1, 1)])
def test_counts_product_equals_the_float64_product(step, total_scale):
    from results_analysis.bootstrap import counts_product, resample_counts
    rng = np.random.default_rng(3)
    clusters = 4000
    counts = resample_counts(clusters, 300, 2)
    # rank sums and counts (multiples of 1/2, 1/16, whole), thirds, or sums so large that float32 is not exact
    sums = rng.integers(0, 50, (clusters, 7)) * step * total_scale
    want = counts.astype(np.float64) @ sums
    got = counts_product(counts, sums, clusters)
    assert got.dtype == np.float64 and np.array_equal(got, want)
    if step in (1 / 3, 0.1) or total_scale > 1:  # what a plain float32 product would get wrong
        assert not np.array_equal((counts @ sums.astype(np.float32)).astype(np.float64), want)


@pytest.mark.parametrize("k", [2, 3, 5, 6, 7])
def test_tie_sum_from_tie_sizes_equals_runs_of_sorted_rows(k):
    from results_analysis.friedman import _tie_sum
    rng = np.random.default_rng(k)
    for r in (_row_ranks(rng.integers(0, k, (3000, k)).astype(float)), _row_ranks(rng.random((50, k))),
              np.full((10, k), (k + 1) / 2.0)):
        s = np.sort(r, axis=1)  # sum of t^3 - t over the runs of equal values of each sorted row
        starts = np.ones(s.shape, dtype=bool)
        starts[:, 1:] = s[:, 1:] != s[:, :-1]
        t = np.bincount((np.cumsum(starts, axis=1) - 1 + (np.arange(len(s)) * k)[:, None]).ravel()).astype(float)
        assert _tie_sum(r) == float(np.sum(t ** 3 - t))


@pytest.mark.parametrize("shape", [(5000,), (5000, 3), (5000, 3, 3), (0, 4)])
def test_cluster_totals_equal_add_at(shape):
    from results_analysis.bootstrap import cluster_totals
    rng = np.random.default_rng(len(shape))
    cluster = rng.integers(0, 700, shape[0])
    values = rng.random(shape) / 3.0  # inexact sums: the order of additions must be np.add.at's
    want = np.zeros((700,) + shape[1:])
    np.add.at(want, cluster, values)
    got = cluster_totals(cluster, 700, values)
    assert got.shape == want.shape and np.array_equal(got, want)
