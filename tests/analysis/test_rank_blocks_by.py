"""rank_blocks_by / rank_blocks_with_trials build each criterion's trials x conditions matrix once and split it
by level (stimulus, speaker, participant group): every level's blocks are bit-identical to what rank_blocks
gives for that level's rows, the path the breakdowns took before (two matrices per level and criterion), on
frames with ties, missing ranks, missing conditions, shuffled rows, levels that change within a trial and
duplicated answers split between levels (the per-level fallback)."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from results_analysis.analysis import group_breakdown
from results_analysis.agreement import stimulus_agreement
from results_analysis.friedman import friedman_ranks
from results_analysis.ranks import RankBlocks, place_shares, rank_blocks, rank_blocks_by, rank_blocks_with_trials
from results_analysis.simulate import simulate_results

CONDS = ["FaceCapGes", "DiffSHEG", "CaMN"]


def _same(a: RankBlocks, b: RankBlocks) -> None:
    assert a.block == b.block and a.conditions == b.conditions
    for x, y in ((a.values, b.values), (a.ranks, b.ranks)):
        assert x.shape == y.shape and np.array_equal(x, y, equal_nan=True)
    assert a.participants.tolist() == b.participants.tolist()


def _messy(seed: int) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    df = simulate_results(int(rng.integers(2, 15)), int(rng.integers(1, 4)), seed=seed, n_practice=0, n_attention=0)
    m = rng.random(len(df))
    df.loc[m < 0.1, "rank"] = 1.0                      # ties
    df.loc[(m > 0.1) & (m < 0.13), "rank"] = np.nan    # missing answers: incomplete trials
    df["group"] = np.where(rng.random(len(df)) < 0.5, "g1", "g2") if seed % 2 else \
        df["participant"].map(lambda p: f"g{int(p[1:]) % 3}")  # per row (changes within trials) or per participant
    if seed % 3 == 0:  # a complete trial repeated under another level: its level is ambiguous
        dup = df[(df.participant == df.participant.iloc[0]) & (df.trial_index == df.trial_index.iloc[0])]
        df = pd.concat([df, dup.assign(group="g9")])
    return df.sample(frac=1, random_state=seed)


@pytest.mark.parametrize("seed", range(8))
@pytest.mark.parametrize("block", ["participant", "trial"])
def test_split_equals_rank_blocks_per_level(seed: int, block: str) -> None:
    df = _messy(seed)
    for levels in (df["group"], df["stimulus"]):
        for crit in ("realism", "diversity", "absent"):
            split = rank_blocks_by(df, crit, levels, block=block, conditions=CONDS)
            assert list(split) == sorted(levels.unique())
            for level, (b, tb) in split.items():
                part = df[levels == level]
                _same(b, rank_blocks(part, crit, block=block, conditions=CONDS))
                _same(tb, rank_blocks(part, crit, block="trial", conditions=CONDS))
        both = rank_blocks_with_trials(df, "realism", block="participant", conditions=CONDS)
        _same(both[0], rank_blocks(df, "realism", block="participant", conditions=CONDS))
        _same(both[1], rank_blocks(df, "realism", block="trial", conditions=CONDS))


def _breakdown_per_level(df, column, criteria, block):
    """group_breakdown as it was: two rank_blocks per level and criterion, on the level's rows."""
    rows = []
    for level, sub in df.groupby(df[column].fillna("(none)").astype(str), sort=True):
        for crit in criteria:
            b = rank_blocks(sub, crit, block=block, conditions=CONDS)
            row = {"group": column, "level": level, "criterion": crit, "n_blocks": b.n,
                   "n_participants": int(np.unique(b.participants).size)}
            if b.n >= 2:
                fr = friedman_ranks(b.ranks)
                row.update(chi2=fr.chi2, df=fr.df, p=fr.p, kendall_w=fr.kendall_w)
                row.update({f"mean_rank_{c}": v for c, v in zip(CONDS, fr.mean_rank)})
            else:
                row.update(chi2=np.nan, df=len(CONDS) - 1, p=np.nan, kendall_w=np.nan)
                row.update({f"mean_rank_{c}": (float(b.ranks[0, i]) if b.n else np.nan) for i, c in enumerate(CONDS)})
            if b.n:
                tb = rank_blocks(sub, crit, block="trial", conditions=CONDS)
                first = place_shares(tb.ranks)[:, 0]
                row.update({f"share_rank_1_{c}": float(first[i]) for i, c in enumerate(CONDS)})
            rows.append(row)
    return pd.DataFrame(rows)


@pytest.mark.parametrize("seed", range(4))
def test_breakdown_and_agreement_unchanged(seed: int) -> None:
    df = _messy(seed)
    for block in ("participant", "trial"):
        for column in ("group", "speaker"):
            pd.testing.assert_frame_equal(group_breakdown(df, column, conditions=CONDS, criteria=["realism", "diversity"],
                                                          block=block),
                                          _breakdown_per_level(df, column, ["realism", "diversity"], block),
                                          check_exact=True)
    got = stimulus_agreement(df, conditions=CONDS, criteria=["realism", "diversity"])
    for (crit, stim), row in got.set_index(["criterion", "stimulus"]).iterrows():
        part = df[(df.criterion == crit) & (df.stimulus == stim)]
        b = rank_blocks(part, crit, block="participant", conditions=CONDS)
        assert row["n_raters"] == b.n
        if b.n >= 2:
            assert row["kendall_w"] == friedman_ranks(b.ranks).kendall_w


@pytest.mark.parametrize("k", [1, 2, 3, 5, 16, 17])
def test_row_ranks_equal_rankdata(k: int) -> None:
    """Average ranks by comparison within the row: the very numbers of scipy's rankdata (ties, inf, NaN)."""
    from scipy.stats import rankdata

    from results_analysis.ranks import _row_ranks, within_block_ranks

    rng = np.random.default_rng(k)
    for x in (rng.integers(1, 4, (400, k)).astype(float), rng.random((400, k)), np.round(rng.random((400, k)) * 4) / 2,
              np.where(rng.random((400, k)) < 0.2, np.inf, rng.integers(1, 4, (400, k))),
              np.where(rng.random((400, k)) < 0.1, np.nan, rng.random((400, k))), np.zeros((0, k))):
        ref = rankdata(x, axis=1, method="average")
        for got in (_row_ranks(x), within_block_ranks(x)):
            assert got.dtype == ref.dtype and np.array_equal(got, ref, equal_nan=True)


def test_one_matrix_per_criterion_in_an_analysis(monkeypatch) -> None:
    """run_analysis builds each criterion's matrix once for its blocks, breakdowns and agreement table, and
    the shared matrices give the numbers each function gives on its own."""
    import results_analysis.ranks as ranks
    from results_analysis.analysis import run_analysis

    df = simulate_results(12, 3, seed=4, n_practice=0, n_attention=0)
    calls = []
    real = ranks._wide_codes  # every matrix is built there, from a frame's codes or a subset's
    monkeypatch.setattr(ranks, "_wide_codes", lambda *a, **k: calls.append(1) or real(*a, **k))
    a = run_analysis(df, groups=["speaker", "device"], n_boot=0)
    assert len(calls) == 3  # realism, synchronization, diversity
    monkeypatch.undo()
    alone = stimulus_agreement(df, conditions=a.conditions, criteria=list(a.criteria))
    pd.testing.assert_frame_equal(alone, a.agreement, check_exact=True)
    pd.testing.assert_frame_equal(group_breakdown(df, "device", conditions=a.conditions, criteria=list(a.criteria)),
                                  a.groups["device"], check_exact=True)


def test_participant_index_is_np_unique() -> None:
    from results_analysis.ranks import participant_index

    rng = np.random.default_rng(3)
    names = np.array([f"P{i:03d}" for i in rng.integers(0, 50, 300)], dtype=object)
    for p in (np.sort(names), names, names[:1], names[:0], np.array(["P2", "P10", "P10"], dtype=object)):
        ids, which = participant_index(p)
        ref_ids, ref_which = np.unique(p, return_inverse=True)
        assert ids.tolist() == ref_ids.tolist() and np.array_equal(which, ref_which)


def test_ties_is_isclose() -> None:
    """Equality stands in for isclose only where the two agree (half-integer ranks); elsewhere isclose."""
    from results_analysis.ranks import ties

    rng = np.random.default_rng(5)
    half = rng.integers(2, 12, (200, 4)) / 2.0
    for r in (half, half + 1e-9, rng.random((200, 4)), np.where(half > 3, np.nan, half), half * 1000,
              np.zeros((0, 4))):
        a, b = r[:, :, None], r[:, None, :]
        assert np.array_equal(ties(a, b), np.isclose(a, b))


@pytest.mark.parametrize("seed", range(8))
def test_table_from_frame_codes_equals_table_from_text_columns(seed: int) -> None:
    """criterion_table (codes factorized once for the frame) gives the matrix _criterion_table builds from the
    criterion's own rows: same rows, trials, answers, owners and ranks, on messy frames (ties, gaps, duplicates,
    shuffled rows, a criterion without rows)."""
    from results_analysis.codes import frame_codes
    from results_analysis.ranks import _criterion_table, criterion_table

    df = _messy(seed)
    codes = frame_codes(df)
    for crit in ("realism", "diversity", "absent"):
        want, got = _criterion_table(df, crit, CONDS), criterion_table(codes, crit, CONDS)
        assert np.array_equal(got.rows, want.rows) and got.n_trials == want.n_trials
        assert all(np.array_equal(g, w) for g, w in zip(got.answers, want.answers))
        assert np.array_equal(got.complete, want.complete)
        assert got.owner.tolist() == want.owner.tolist() and got.owner.dtype == want.owner.dtype
        assert np.array_equal(got.values, want.values, equal_nan=True)
