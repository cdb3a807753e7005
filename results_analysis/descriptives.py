"""Per-condition descriptions of the rankings: mean rank with a participant bootstrap CI, median rank,
share of answers at each rank, and counts.
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from results_analysis.bootstrap import cluster_totals, counts_product, resample_counts, resample_weights
from results_analysis.ranks import RankBlocks, as_blocks, participant_index, place_shares


def bootstrap_weights(n_participants: int, n_boot: int, seed: int, *, background: bool = False) -> np.ndarray | None:
    """(n_boot, n_participants) multiplicities (as floats, read-only) of each participant in each resample
    (drawn with replacement; ``background``: see :func:`results_analysis.bootstrap.shared_draw`).

    Resampling whole participants keeps a participant's correlated trials together. These are the resamples
    of :func:`results_analysis.bootstrap.resample_weights` (the index draws scipy.stats.bootstrap makes, a
    multinomial sample of the participants), so within :func:`results_analysis.bootstrap.shared_resamples`
    the mean-rank, Bradley-Terry and effect-size intervals share one matrix: a 10,000-participant study
    drew a second (multinomial) matrix of the same distribution for 1.2 s and 160 MB.
    """
    return resample_weights(n_participants, n_boot, seed, background=background)


def per_participant_sums(blocks: RankBlocks, values: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Participants (sorted), the (P, k) sums of ``values`` (default: the block ranks) and (P,) block counts."""
    values = blocks.ranks if values is None else values
    ids, inverse = participant_index(blocks.participants)
    sums = cluster_totals(inverse, ids.size, values)
    counts = np.bincount(inverse, minlength=ids.size).astype(float)
    return ids, sums, counts


def condition_summary(blocks: RankBlocks | pd.DataFrame, criterion: str | None = None, *, n_boot: int = 2000,
                      ci: float = 0.95, seed: int = 0) -> pd.DataFrame:
    """Per condition: n blocks, n participants, mean rank with a percentile bootstrap CI over participants,
    median rank and the share of blocks that put the condition at each place (``share_rank_1`` ...; a tied
    answer is shared between the places it spans, so each condition's shares sum to 1).

    ``blocks``: a :class:`RankBlocks`, or a tidy results DataFrame with the ``criterion`` to describe
    (trials as blocks; practice and attention-check trials left out).

    >>> import numpy as np
    >>> from results_analysis.ranks import RankBlocks, as_blocks
    >>> r = np.array([[1, 2, 3], [1, 3, 2], [2, 1, 3], [1, 2, 3]], dtype=float)
    >>> b = RankBlocks(r, r, ["A", "B", "C"], np.array(["P1", "P1", "P2", "P2"]), "trial")
    >>> condition_summary(b, n_boot=200)[["condition", "mean_rank", "share_rank_1"]].values.tolist()
    [['A', 1.25, 0.75], ['B', 2.0, 0.25], ['C', 2.75, 0.0]]
    """
    blocks = as_blocks(blocks, criterion)
    ranks = blocks.ranks
    n, k = ranks.shape
    out = pd.DataFrame({"condition": blocks.conditions, "n": n,
                        "n_participants": int(participant_index(blocks.participants)[0].size)})
    out["mean_rank"] = ranks.mean(axis=0) if n else np.nan
    lo, hi = bootstrap_mean_rank_ci(blocks, n_boot=n_boot, ci=ci, seed=seed)
    out["ci_low"], out["ci_high"] = lo, hi
    out["median_rank"] = np.median(ranks, axis=0) if n else np.nan
    shares = place_shares(ranks)
    for r in range(1, k + 1):
        out[f"share_rank_{r}"] = shares[:, r - 1]
    out.attrs.update(ci=ci, n_boot=n_boot, seed=seed)
    return out


def bootstrap_mean_rank_ci(blocks: RankBlocks, *, n_boot: int = 2000, ci: float = 0.95,
                           seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Percentile bootstrap CI of each condition's mean rank, resampling participants (seeded)."""
    k = blocks.k
    if blocks.n == 0 or n_boot <= 0:
        return np.full(k, np.nan), np.full(k, np.nan)
    _, sums, counts = per_participant_sums(blocks)
    # one product for the rank sums and the block counts, exact in float32 (see bootstrap.counts_product)
    w = resample_counts(sums.shape[0], n_boot, seed)
    both = counts_product(w, np.column_stack([sums, counts]), sums.shape[0])
    means = both[:, :-1] / both[:, -1][:, None]
    a = (1.0 - ci) / 2.0
    return np.quantile(means, a, axis=0), np.quantile(means, 1.0 - a, axis=0)
