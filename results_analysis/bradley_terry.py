"""Bradley-Terry strengths from rankings decomposed into pairwise wins, with a participant bootstrap.

Each block (a ranking of k conditions) gives k(k-1)/2 pairwise outcomes: the better-ranked condition
wins, a tie gives half a win to each. The strengths maximise the Bradley-Terry likelihood
P(i beats j) = p_i / (p_i + p_j), fitted with Hunter's (2004) MM algorithm. A tiny symmetric pseudo-count
(``prior`` wins each way per pair) keeps the estimate finite when a condition never wins.
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from results_analysis.descriptives import bootstrap_weights
from results_analysis.ranks import RankBlocks, as_blocks


def pairwise_wins(ranks: np.ndarray) -> np.ndarray:
    """(k, k) matrix: wins[i, j] = number of blocks ranking i better (lower) than j, ties count 1/2.

    >>> pairwise_wins(np.array([[1, 2, 3], [1.5, 1.5, 3]])).tolist()
    [[0.0, 1.5, 2.0], [0.5, 0.0, 2.0], [0.0, 0.0, 0.0]]
    """
    r = np.asarray(ranks, dtype=float)
    a = r[:, :, None]
    b = r[:, None, :]
    w = (a < b).sum(axis=0) + 0.5 * np.isclose(a, b).sum(axis=0)
    np.fill_diagonal(w, 0.0)
    return w.astype(float)


def fit_bradley_terry(wins: np.ndarray, *, prior: float = 1e-3, tol: float = 1e-10,
                      max_iter: int = 10_000) -> np.ndarray:
    """Bradley-Terry strengths (summing to 1) of one (k, k) wins matrix or a stack (B, k, k) at once.

    >>> p = fit_bradley_terry(np.array([[0, 8, 8], [2, 0, 5], [2, 5, 0]], dtype=float))
    >>> bool(p[0] > p[1]), bool(np.isclose(p[1], p[2]))
    (True, True)
    """
    w = np.asarray(wins, dtype=float)
    single = w.ndim == 2
    if single:
        w = w[None]
    k = w.shape[-1]
    off = ~np.eye(k, dtype=bool)
    w = w + prior * off
    n_ij = w + np.swapaxes(w, 1, 2)
    total_wins = w.sum(axis=2)
    p = np.full(w.shape[:2], 1.0 / k)
    for _ in range(max_iter):
        denom = (n_ij / (p[:, :, None] + p[:, None, :]) * off).sum(axis=2)
        new = total_wins / denom
        new /= new.sum(axis=1, keepdims=True)
        done = np.max(np.abs(new - p)) < tol
        p = new
        if done:
            break
    return p[0] if single else p


def bradley_terry(blocks: RankBlocks | pd.DataFrame, criterion: str | None = None, *, n_boot: int = 1000,
                  ci: float = 0.95, seed: int = 0) -> pd.DataFrame:
    """Bradley-Terry strength per condition with percentile bootstrap intervals over participants.

    ``blocks``: a :class:`RankBlocks`, or a tidy results DataFrame with the ``criterion`` to fit.

    Columns: condition, strength (sums to 1 over conditions), ci_low, ci_high, log_strength (centred
    log-strength; differences are log-odds of winning), win_rate (share of its pairwise comparisons won).
    """
    blocks = as_blocks(blocks, criterion)
    k = blocks.k
    wins = pairwise_wins(blocks.ranks)
    p = fit_bradley_terry(wins)
    out = pd.DataFrame({"condition": blocks.conditions, "strength": p})
    lo = hi = np.full(k, np.nan)
    if n_boot > 0 and blocks.n:
        ids, inverse = np.unique(blocks.participants, return_inverse=True)
        r = blocks.ranks
        per = ((r[:, :, None] < r[:, None, :]) + 0.5 * np.isclose(r[:, :, None], r[:, None, :])).astype(float)
        per[:, np.arange(k), np.arange(k)] = 0.0
        by_participant = np.zeros((ids.size, k, k))
        np.add.at(by_participant, inverse, per)
        weights = bootstrap_weights(ids.size, n_boot, seed).astype(float)
        boot = fit_bradley_terry(np.einsum("bp,pij->bij", weights, by_participant), tol=1e-8)
        a = (1.0 - ci) / 2.0
        lo, hi = np.quantile(boot, a, axis=0), np.quantile(boot, 1.0 - a, axis=0)
    out["ci_low"], out["ci_high"] = lo, hi
    logp = np.log(p)
    out["log_strength"] = logp - logp.mean()
    games = wins + wins.T
    out["win_rate"] = wins.sum(axis=1) / np.maximum(games.sum(axis=1), 1e-12)
    out.attrs.update(n_boot=n_boot, ci=ci, seed=seed)
    return out
