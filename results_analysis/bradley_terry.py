"""Bradley-Terry strengths from rankings decomposed into pairwise wins, with a participant bootstrap.

Each block (a ranking of k conditions) gives k(k-1)/2 pairwise outcomes: the better-ranked condition
wins, a tie gives half a win to each. The strengths maximise the Bradley-Terry likelihood
P(i beats j) = p_i / (p_i + p_j), fitted by Newton's method on the log-strengths (the log-likelihood is
concave; each step is halved until it does not decrease) until the largest step is below ``tol``; if
``max_iter`` steps do not get there a :class:`ConvergenceWarning` says so: the fit never stops silently.

The maximum-likelihood estimate exists only when the wins link every condition to every other both ways
(the directed "i beat j at least once" graph is strongly connected; Ford 1957). When they do not, e.g. a
condition that never won, :func:`estimability` names the conditions whose strength cannot be estimated,
and :func:`bradley_terry` reports them as not estimable (strength NaN, ``estimable`` False, ``note`` says
why) instead of the number a pseudo-count would make up. The strengths of the others are the
maximum-likelihood estimates among themselves, which is the limit of the full fit (the conditions they
always beat tend to 0). Bootstrap resamples are fitted with a pseudo-count of ``BOOT_PRIOR`` wins each
way per pair, so that a resample in which some condition happens never to win stays finite.
"""
from __future__ import annotations

import warnings

import numpy as np
import pandas as pd
from scipy.sparse.csgraph import connected_components

from results_analysis.bootstrap import cluster_totals, counts_product, resample_counts
from results_analysis.ranks import RankBlocks, as_blocks, participant_index, ties

#: Pseudo-count (wins each way per pair) that keeps bootstrap resamples with a never-winning condition finite.
BOOT_PRIOR = 1e-3


class ConvergenceWarning(UserWarning):
    """The Bradley-Terry fit reached its iteration cap before converging."""


def pairwise_wins(ranks: np.ndarray) -> np.ndarray:
    """(k, k) matrix: wins[i, j] = number of blocks ranking i better (lower) than j, ties count 1/2.

    >>> pairwise_wins(np.array([[1, 2, 3], [1.5, 1.5, 3]])).tolist()
    [[0.0, 1.5, 2.0], [0.5, 0.0, 2.0], [0.0, 0.0, 0.0]]
    """
    r = np.asarray(ranks, dtype=float)
    a = r[:, :, None]
    b = r[:, None, :]
    w = (a < b).sum(axis=0) + 0.5 * ties(a, b).sum(axis=0)
    np.fill_diagonal(w, 0.0)
    return w.astype(float)


def estimability(wins: np.ndarray, names: list[str] | None = None) -> tuple[np.ndarray, list[str]]:
    """Which strengths a (k, k) wins matrix can estimate, and a note for each one it cannot.

    All of them when every condition is linked to every other both ways. Otherwise the leading group (the
    strongly connected conditions that no one outside beat) is estimable when it has at least two members,
    and no condition is when it has one (its strength tends to 1, all others to 0) or when there are several.

    >>> est, notes = estimability(np.array([[0, 3, 4], [1, 0, 4], [0, 0, 0]], dtype=float))
    >>> est.tolist(), notes
    ([True, True, False], ['', '', 'never won'])
    """
    w = np.asarray(wins, dtype=float)
    k = w.shape[0]
    n_comp, label = connected_components(w > 0, directed=True, connection="strong")
    if n_comp == 1:
        return np.ones(k, dtype=bool), [""] * k
    won, lost = w.sum(axis=1), w.sum(axis=0)
    # A leading group: no condition outside it won against any member.
    leading = [g for g in range(n_comp) if not (w[np.ix_(label != g, label == g)] > 0).any()]
    estimable = np.zeros(k, dtype=bool)
    if len(leading) == 1 and np.count_nonzero(label == leading[0]) >= 2:
        estimable = label == leading[0]
    notes = []
    for i in range(k):
        if estimable[i]:
            notes.append("")
        elif won[i] == 0:
            notes.append("never won")
        elif lost[i] == 0:
            notes.append("never lost")
        elif estimable.any():
            names = names if names is not None else [str(j) for j in range(k)]
            notes.append("always beaten by " + ", ".join(names[j] for j in np.flatnonzero(estimable)))
        else:
            notes.append("not estimable: the wins do not link every condition both ways")
    return estimable, notes


def fit_bradley_terry(wins: np.ndarray, *, prior: float = 0.0, tol: float = 1e-10,
                      max_iter: int = 100) -> np.ndarray:
    """Bradley-Terry strengths (summing to 1) of one (k, k) wins matrix or a stack (B, k, k) at once.

    ``prior`` adds that many wins each way to every pair (a pseudo-count; 0: plain maximum likelihood, which
    needs every condition linked to every other both ways, else ValueError). Warns with
    :class:`ConvergenceWarning` when ``max_iter`` Newton steps do not bring the largest change of a
    log-strength below ``tol``.

    >>> p = fit_bradley_terry(np.array([[0, 8, 8], [2, 0, 5], [2, 5, 0]], dtype=float))
    >>> bool(p[0] > p[1]), bool(np.isclose(p[1], p[2]))
    (True, True)
    """
    w = np.asarray(wins, dtype=float)
    single = w.ndim == 2
    if single:
        w = w[None]
    n_fits, k = w.shape[0], w.shape[-1]
    off = ~np.eye(k, dtype=bool)
    w = w + prior * off
    if prior <= 0:
        broken = [b for b in range(n_fits) if connected_components(w[b] > 0, directed=True,
                                                                   connection="strong")[0] > 1]
        if broken:
            raise ValueError("the wins do not link every condition to every other both ways (e.g. a condition "
                         "never won), so the maximum-likelihood strengths are not finite: see estimability() "
                         "or pass prior > 0")
    games = w + np.swapaxes(w, 1, 2)
    ones = np.ones((k, k))
    theta = np.zeros((n_fits, k))

    def loglik(th: np.ndarray) -> np.ndarray:
        d = th[:, :, None] - th[:, None, :]
        return (w * (d - np.logaddexp(0.0, d)) * off).sum(axis=(1, 2))

    current = loglik(theta)
    converged = False
    for _ in range(max_iter):
        d = theta[:, :, None] - theta[:, None, :]
        pi = 1.0 / (1.0 + np.exp(-d))                            # P(i beats j)
        grad = ((w - games * pi) * off).sum(axis=2)
        info = games * pi * (1.0 - pi) * off                     # minus the off-diagonal Hessian
        neg_hess = np.zeros_like(info)
        neg_hess -= info
        idx = np.arange(k)
        neg_hess[:, idx, idx] = info.sum(axis=2)
        # The likelihood only sees differences of log-strengths: adding 11' removes that null direction, and
        # the step it gives sums to 0 because the gradient does.
        step = np.linalg.solve(neg_hess + ones, grad[:, :, None])[:, :, 0]
        size = np.ones(n_fits)
        for _halving in range(60):
            trial = theta + size[:, None] * step
            new = loglik(trial)
            worse = new < current - 1e-12 * np.abs(current)
            if not worse.any():
                break
            size = np.where(worse, size / 2.0, size)
        theta, current = trial, new
        if np.max(np.abs(size[:, None] * step)) < tol:
            converged = True
            break
    if not converged:
        warnings.warn(f"Bradley-Terry fit did not converge in {max_iter} Newton steps (largest last change of a "
                      f"log-strength {np.max(np.abs(size[:, None] * step)):.2g} > {tol:g})", ConvergenceWarning,
                      stacklevel=2)
    p = np.exp(theta - theta.max(axis=1, keepdims=True))
    p /= p.sum(axis=1, keepdims=True)
    return p[0] if single else p


def bradley_terry(blocks: RankBlocks | pd.DataFrame, criterion: str | None = None, *, n_boot: int = 1000,
                  ci: float = 0.95, seed: int = 0) -> pd.DataFrame:
    """Bradley-Terry strength per condition with percentile bootstrap intervals over participants.

    ``blocks``: a :class:`RankBlocks`, or a tidy results DataFrame with the ``criterion`` to fit.

    Columns: condition, strength (sums to 1 over the estimable conditions), ci_low, ci_high, log_strength
    (centred log-strength; differences are log-odds of winning), win_rate (share of its pairwise
    comparisons won), estimable, note (why a strength is not estimable; NaN strength and interval then).
    """
    blocks = as_blocks(blocks, criterion)
    k = blocks.k
    wins = pairwise_wins(blocks.ranks)
    estimable, notes = estimability(wins, blocks.conditions)
    keep = np.flatnonzero(estimable)
    p = np.full(k, np.nan)
    if keep.size:
        p[keep] = fit_bradley_terry(wins[np.ix_(keep, keep)])
    out = pd.DataFrame({"condition": blocks.conditions, "strength": p})
    lo, hi = np.full(k, np.nan), np.full(k, np.nan)
    if n_boot > 0 and blocks.n and keep.size:
        ids, inverse = participant_index(blocks.participants)
        r = blocks.ranks
        per = ((r[:, :, None] < r[:, None, :]) + 0.5 * ties(r[:, :, None], r[:, None, :])).astype(float)
        per[:, np.arange(k), np.arange(k)] = 0.0
        by_participant = cluster_totals(inverse, ids.size, per)
        weights = resample_counts(ids.size, n_boot, seed)
        # one matrix product (BLAS) rather than einsum's own loop; the counts are multiples of 1/2 and the
        # weights integers, so every sum is exact whatever the order of additions (and in float32: see
        # bootstrap.counts_product)
        resampled = counts_product(weights, by_participant.reshape(ids.size, k * k), ids.size)
        resampled = resampled.reshape(-1, k, k)[:, keep][:, :, keep]
        boot = fit_bradley_terry(resampled, prior=BOOT_PRIOR, tol=1e-8)
        a = (1.0 - ci) / 2.0
        lo[keep], hi[keep] = np.quantile(boot, a, axis=0), np.quantile(boot, 1.0 - a, axis=0)
    out["ci_low"], out["ci_high"] = lo, hi
    logp = np.log(p)
    out["log_strength"] = logp - np.nanmean(logp) if keep.size else np.nan
    games = wins + wins.T
    out["win_rate"] = wins.sum(axis=1) / np.maximum(games.sum(axis=1), 1e-12)
    out["estimable"] = estimable
    out["note"] = notes
    out.attrs.update(n_boot=n_boot, ci=ci, seed=seed)
    return out
