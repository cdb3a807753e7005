"""Skillings-Mack test (Skillings & Mack 1981): Friedman's test for blocks with missing observations.

In each block the observed values are ranked 1..k_i (average ranks for ties); a missing condition gets
the block's mean rank (k_i + 1)/2, i.e. contributes nothing. Adjusted rank sums
A_j = sum_i sqrt(12 / (k_i + 1)) (r_ij - (k_i + 1)/2) have covariance Sigma with
Sigma_jl = -(number of blocks where both j and l are observed) and Sigma_jj = -sum_{l != j} Sigma_jl;
SM = A' Sigma^- A (generalised inverse) is compared with chi2(k - 1). Blocks with fewer than two
observations carry no information and are dropped. With no missing values SM is Friedman's statistic
without tie correction.

The chi-squared approximation can be poor with few blocks or many missing values, so, like R's
``Skillings.Mack(..., simulate.p.value = TRUE)``, a Monte Carlo permutation p-value is offered too: under
H0 the observed ranks are exchangeable within each block, so they are shuffled among each block's observed
cells ``n_perm`` times and ``p = (1 + #{SM* >= SM}) / (n_perm + 1)``.
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
    #: Monte Carlo permutation p-value (``None`` unless asked for) and the number of permutations behind it.
    p_permutation: float | None = None
    n_permutations: int = 0


def skillings_mack(values: np.ndarray, n_perm: int = 0, seed: int = 0) -> SkillingsMackResult:
    """Skillings-Mack test of an (n blocks, k conditions) array with NaN where a block lacks a condition.

    ``n_perm > 0`` adds a permutation p-value from that many within-block shuffles (seeded: the same
    ``seed`` gives the same p).

    >>> v = np.array([[1, 2, 3], [1, 3, np.nan], [2, 1, 3], [np.nan, 1, 2], [1, 2, 3]])
    >>> r = skillings_mack(v, n_perm=999, seed=1)
    >>> r.df, r.n_blocks, r.n_missing, r.n_permutations
    (2, 5, 2, 999)
    >>> 0 < r.p_permutation <= 1
    True
    """
    v = np.asarray(values, dtype=float)
    observed = ~np.isnan(v)
    keep = observed.sum(axis=1) >= 2
    v, observed = v[keep], observed[keep]
    n, k = v.shape
    k_i = observed.sum(axis=1).astype(float)
    # Rank observed values within each block; NaNs sort last and are masked out afterwards.
    ranks = stats.rankdata(np.where(observed, v, np.inf), axis=1, method="average")
    weighted = np.sqrt(12.0 / (k_i + 1))[:, None] * np.where(observed, ranks - (k_i[:, None] + 1) / 2, 0.0)
    both = observed.T.astype(float) @ observed.astype(float)
    sigma = -both
    np.fill_diagonal(sigma, 0.0)
    np.fill_diagonal(sigma, -sigma.sum(axis=1))
    sigma_inv = np.linalg.pinv(sigma)
    a = weighted.sum(axis=0)
    sm = float(a @ sigma_inv @ a) if n else 0.0
    p_perm = None
    if n_perm > 0 and n:
        null = _permuted_statistics(weighted, observed, sigma_inv, int(n_perm), seed)
        # a small tolerance so that permutations equal to the observed arrangement count as "as extreme"
        p_perm = float((1 + np.count_nonzero(null >= sm - 1e-9 * max(1.0, abs(sm)))) / (n_perm + 1))
    return SkillingsMackResult(statistic=sm, df=k - 1, p=float(stats.chi2.sf(sm, k - 1)), n_blocks=int(n),
                               n_missing=int((~observed).sum()), p_permutation=p_perm,
                               n_permutations=int(n_perm) if p_perm is not None else 0)


def _permuted_statistics(weighted: np.ndarray, observed: np.ndarray, sigma_inv: np.ndarray, n_perm: int,
                         seed: int) -> np.ndarray:
    """SM for ``n_perm`` arrangements with each block's weighted ranks shuffled among its observed cells.

    Missing cells stay missing (and zero), so the covariance matrix is the same for every arrangement.
    Done in chunks of permutations, each a handful of batched numpy operations over (chunk, n, k).
    """
    rng = np.random.default_rng(seed)
    n, k = weighted.shape
    # each block's observed values first (in column order), its missing cells last
    source = np.argsort(~observed, axis=1, kind="stable")
    values_first = np.take_along_axis(weighted, source, axis=1)
    chunk = max(1, min(n_perm, 4_000_000 // max(1, n * k)))
    out = np.empty(n_perm)
    for start in range(0, n_perm, chunk):
        m = min(chunk, n_perm - start)
        keys = rng.random((m, n, k))
        keys[:, ~observed] = np.inf  # missing cells sort last: the observed values land on observed cells
        target = np.argsort(keys, axis=2)
        shuffled = np.zeros((m, n, k))
        np.put_along_axis(shuffled, target, np.broadcast_to(values_first, (m, n, k)), axis=2)
        a = shuffled.sum(axis=1)
        out[start:start + m] = np.einsum("bi,ij,bj->b", a, sigma_inv, a)
    return out
