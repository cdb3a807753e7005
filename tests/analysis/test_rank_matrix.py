"""rank_blocks builds its trials x conditions matrix without pandas' pivot_table: the blocks (values, order,
participants) equal those pivot_table + groupby give, on frames with ties, missing ranks, duplicate answers,
missing conditions and shuffled rows."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from scipy.stats import rankdata

from results_analysis.ranks import rank_blocks
from results_analysis.simulate import simulate_results


def _pivot_reference(df, criterion, block, conditions, complete_only):
    sub = df[df["criterion"] == criterion]
    if conditions is None:
        conditions = sorted(df["condition"].unique())
    wide = sub.pivot_table(index=["participant", "trial_index"], columns="condition", values="rank",
                           aggfunc="first", observed=True).reindex(columns=conditions)
    if complete_only:
        wide = wide.dropna(axis=0, how="any")
    raw = wide.to_numpy(dtype=float)
    missing = np.isnan(raw)
    tr = np.where(missing, np.nan, rankdata(np.where(missing, np.inf, raw), axis=1, method="average")) \
        if raw.size else raw
    tr = pd.DataFrame(tr, index=wide.index, columns=wide.columns)
    if block == "participant":
        tr = tr.groupby(level="participant", sort=True).mean()
    return tr.to_numpy(dtype=float), tr.index.get_level_values("participant").astype(str).to_numpy()


def _messy(seed: int) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    df = simulate_results(int(rng.integers(1, 15)), int(rng.integers(1, 4)), seed=seed)
    df = df[~df.is_practice & ~df.is_attention_check].copy()
    m = rng.random(len(df))
    df.loc[m < 0.1, "rank"] = 1.0                      # ties
    df.loc[(m > 0.1) & (m < 0.15), "rank"] = np.nan    # missing answers
    if seed % 3 == 0:                                  # duplicate answers: the first one counts
        df = pd.concat([df, df.sample(5, random_state=seed).assign(rank=2.0)])
    if seed % 4 == 0:
        df = df[df.condition != "CaMN"]
    return df.sample(frac=1, random_state=seed)


@pytest.mark.parametrize("seed", range(12))
def test_rank_blocks_equal_pivot_table(seed: int) -> None:
    df = _messy(seed)
    for crit in ("realism", "diversity", "absent"):
        for block, complete in (("participant", True), ("trial", True), ("trial", False)):
            for conds in (None, ["FaceCapGes", "DiffSHEG", "CaMN"], ["DiffSHEG", "FaceCapGes"]):
                values, who = _pivot_reference(df, crit, block, conds, complete)
                b = rank_blocks(df, crit, block=block, conditions=conds, complete_only=complete)
                assert b.values.shape == values.shape
                assert np.array_equal(b.values, values, equal_nan=True)
                assert b.participants.tolist() == who.tolist()
