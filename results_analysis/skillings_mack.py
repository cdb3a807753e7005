"""Skillings-Mack test (Skillings & Mack 1981): Friedman's test for blocks with missing observations.

In each block the observed values are ranked 1..k_i (average ranks for ties); a missing condition gets
the block's mean rank (k_i + 1)/2, i.e. contributes nothing. Adjusted rank sums
A_j = sum_i sqrt(12 / (k_i + 1)) (r_ij - (k_i + 1)/2) have covariance Sigma with
Sigma_jl = -(number of blocks where both j and l are observed) and Sigma_jj = -sum_{l != j} Sigma_jl;
SM = A' Sigma^- A (generalised inverse) is compared with chi2(k - 1). Blocks with fewer than two
observations carry no information and are dropped. With no missing values SM is Friedman's statistic
without tie correction.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats


@dataclass(frozen=True)
class SkillingsMackResult:
    statistic: float
    df: int
    p: float
    n_blocks: int
    n_missing: int


def skillings_mack(values: np.ndarray) -> SkillingsMackResult:
    """Skillings-Mack test of an (n blocks, k conditions) array with NaN where a block lacks a condition.

    >>> v = np.array([[1, 2, 3], [1, 3, np.nan], [2, 1, 3], [np.nan, 1, 2], [1, 2, 3]])
    >>> r = skillings_mack(v)
    >>> r.df, r.n_blocks, r.n_missing
    (2, 5, 2)
    """
    v = np.asarray(values, dtype=float)
    observed = ~np.isnan(v)
    keep = observed.sum(axis=1) >= 2
    v, observed = v[keep], observed[keep]
    n, k = v.shape
    k_i = observed.sum(axis=1).astype(float)
    # Rank observed values within each block; NaNs sort last and are masked out afterwards.
    ranks = stats.rankdata(np.where(observed, v, np.inf), axis=1, method="average")
    centred = np.where(observed, ranks - (k_i[:, None] + 1) / 2, 0.0)
    a = (np.sqrt(12.0 / (k_i + 1))[:, None] * centred).sum(axis=0)
    both = observed.T.astype(float) @ observed.astype(float)
    sigma = -both
    np.fill_diagonal(sigma, 0.0)
    np.fill_diagonal(sigma, -sigma.sum(axis=1))
    sm = float(a @ np.linalg.pinv(sigma) @ a) if n else 0.0
    return SkillingsMackResult(statistic=sm, df=k - 1, p=float(stats.chi2.sf(sm, k - 1)), n_blocks=int(n),
                               n_missing=int((~observed).sum()))
