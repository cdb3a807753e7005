"""Effect sizes of a rank analysis with intervals: Kendall's W, the matched-pairs rank-biserial r_rb and the
Hodges-Lehmann estimate of a pair's difference of ranks.

* Kendall's W = chi2_F / (n (k-1)), the tie-corrected Friedman statistic over the blocks (as
  :func:`results_analysis.friedman.friedman_ranks`), with a cluster-bootstrap interval.
* r_rb of a pair (a, b): (2 V - T) / T on the non-zero differences d = a - b of the paired block values
  (within-trial ranks, or a participant's mean of them), V the sum of the ranks of |d| belonging to
  positive d, T = n(n+1)/2 (Kerby 2014; the Wilcoxon test's own effect size, positive when a received
  larger, i.e. worse, ranks). Cluster-bootstrap interval.
* Hodges-Lehmann (Hollander & Wolfe 1999, 3.2): the median of the Walsh averages (d_i + d_j)/2, i <= j, of
  the non-zero differences (zeros dropped, as the Wilcoxon test beside it and R's ``wilcox.test`` drop
  them). Its distribution-free interval inverts that Wilcoxon test, as R's ``wilcox.test(conf.int=TRUE)``
  does: with fewer than 50 non-zero differences, no ties and no zeros, the exact interval [W_(C), W_(M+1-C)]
  of the ordered Walsh averages, C the lower alpha/2 quantile of the signed-rank distribution (the achieved
  level is reported); otherwise the shifts d whose normal-approximation test (tie and continuity
  correction, zeros of the shifted differences dropped) is not rejected, whose ends are Walsh averages
  (R's uniroot finds the same points within its 1e-4 tolerance). This interval assumes independent
  blocks, so it is used with participant blocks; with trial blocks (several per participant) the
  Hodges-Lehmann interval is a participant-cluster bootstrap like the others.

Bootstrap intervals resample participants (:mod:`results_analysis.bootstrap`), BCa by default. Each
statistic is a :class:`~results_analysis.bootstrap.ClusterSums` (per-participant counts and rank sums), so
one product of the resample weights with all of them gives every resample's values, and the BCa jackknife
comes from the totals minus each participant's row.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy import stats

from results_analysis.bootstrap import ClusterSums, cluster_bootstrap, cluster_totals
from results_analysis.posthoc import WILCOXON_EXACT_BELOW_N, pairs
from results_analysis.ranks import RankBlocks, participant_index

#: Differences closer than this to zero are zero differences; |d| equal to this many decimals are ties.
_DECIMALS = 10

#: Walsh averages held at once per chunk of bootstrap resamples (bounds memory).
_WALSH_CELLS = 20_000_000


@dataclass(frozen=True)
class HodgesLehmann:
    """The Hodges-Lehmann estimate of a location shift and its distribution-free interval."""

    estimate: float
    ci_low: float
    ci_high: float
    method: str          # 'exact', 'normal approximation' or 'none'
    conf_level: float    # the level achieved (exact intervals are conservative)
    n_nonzero: int


@dataclass(frozen=True)
class EffectSizes:
    """The effect sizes of one criterion: ``kendall_w`` (one row) and ``pairs`` (one row per comparison)."""

    kendall_w: pd.DataFrame
    pairs: pd.DataFrame
    interval: str        # 'bca' or 'percentile'
    n_boot: int
    ci: float
    seed: int


def _nonzero(d: np.ndarray) -> np.ndarray:
    d = np.asarray(d, dtype=float)
    return d[np.round(d, _DECIMALS) != 0]


def walsh_averages(d: np.ndarray) -> np.ndarray:
    """The n(n+1)/2 Walsh averages (d_i + d_j)/2, i <= j, sorted.

    >>> walsh_averages(np.array([1.0, 3.0])).tolist()
    [1.0, 2.0, 3.0]
    """
    d = np.asarray(d, dtype=float)
    i, j = np.triu_indices(d.size)
    return np.sort(np.round((d[i] + d[j]) / 2.0, _DECIMALS))  # rounded: equal averages stay equal


def walsh_distinct(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The distinct values of :func:`walsh_averages` (sorted) and how often each occurs, without building
    the n(n+1)/2 averages: blocks' differences take few distinct values e_l (c_l times each), and the pairs
    i <= j of values e_l <= e_m number c_l c_m (l < m) or c_l (c_l + 1)/2 (l = m). The averages are computed
    as walsh_averages computes them, so the values are the same floats.

    >>> v, c = walsh_distinct(np.array([1.0, 3.0, 1.0]))
    >>> v.tolist(), c.tolist()
    ([1.0, 2.0, 3.0], [3, 2, 1])
    """
    e, c = np.unique(np.asarray(d, dtype=float), return_counts=True)
    li, mi = np.triu_indices(e.size)
    averages = np.round((e[li] + e[mi]) / 2.0, _DECIMALS)
    pairs_ = np.where(li == mi, c[li] * (c[li] + 1) // 2, c[li] * c[mi])
    values, which = np.unique(averages, return_inverse=True)
    return values, np.bincount(which, weights=pairs_, minlength=values.size).astype(np.int64)


def _walsh_at(values: np.ndarray, cum: np.ndarray, q: int) -> float:
    """The q-th (0-based) of the sorted Walsh averages, from :func:`walsh_distinct` (``cum``: cumulative
    counts)."""
    return float(values[int(np.searchsorted(cum, q, side="right"))])


def signed_rank_cdf(n: int) -> np.ndarray:
    """P(T+ <= t) for t = 0 .. n(n+1)/2 under the null (exact distribution of the signed-rank statistic)."""
    counts = np.zeros(n * (n + 1) // 2 + 1)
    counts[0] = 1.0
    for r in range(1, n + 1):  # subsets of {1..n} by their sum
        counts[r:] = counts[r:] + counts[:-r].copy()
    return np.cumsum(counts) / 2.0 ** n


def _z_shifted(values: np.ndarray, counts: np.ndarray, shift: float) -> float:
    """R's wdiff: the continuity- and tie-corrected signed-rank z of x - shift (zeros dropped), for the x that
    holds each of the distinct ``values`` ``counts`` times. Block differences take few distinct values, so
    the signed ranks come from those values' counts (each tie group's average rank is the count before it
    plus (count + 1) / 2), not from ranking every difference again at each step of the search: the rank
    sums are half-integers, exact in any order, so z is the number ranking all of x gives."""
    xd = np.round(values - shift, _DECIMALS)
    keep = xd != 0
    xd, c = xd[keep], counts[keep]
    n = int(c.sum())
    if n == 0:
        return 0.0
    size_of, group = np.unique(np.abs(xd), return_inverse=True)  # tie groups of |x - shift|
    t = np.bincount(group, weights=c, minlength=size_of.size).astype(np.int64)
    positive = np.bincount(group, weights=np.where(xd > 0, c, 0), minlength=size_of.size)
    average_rank = (np.cumsum(t) - t) + (t + 1) / 2.0
    z = float((positive * average_rank).sum()) - n * (n + 1) / 4.0
    sigma = np.sqrt(n * (n + 1) * (2 * n + 1) / 24.0 - np.sum(t ** 3 - t) / 48.0)
    return float((z - np.sign(z) * 0.5) / sigma) if sigma > 0 else 0.0


def _first_below(walsh: np.ndarray, values: np.ndarray, counts: np.ndarray, level: float) -> float:
    """The Walsh average at which z(x - d) first falls below ``level`` as d grows (z is non-increasing in d
    and constant between Walsh averages): binary search over the gaps between them (``walsh``: the distinct
    averages, sorted; x: ``values`` each ``counts`` times, see :func:`_z_shifted`)."""
    mids = np.r_[walsh[0] - 1.0, (walsh[:-1] + walsh[1:]) / 2.0, walsh[-1] + 1.0]
    lo, hi = 0, mids.size - 1   # z(mids[lo]) >= level > z(mids[hi])
    while hi - lo > 1:
        m = (lo + hi) // 2
        if _z_shifted(values, counts, mids[m]) >= level:
            lo = m
        else:
            hi = m
    return float(walsh[hi - 1])


def hodges_lehmann(d: np.ndarray, *, ci: float = 0.95) -> HodgesLehmann:
    """Hodges-Lehmann estimate of the paired differences ``d`` with R's distribution-free interval.

    Hollander & Wolfe (1999), Hamilton depression scale factor IV, x - y of 9 patients (R's ``wilcox.test``
    example): the estimate is 0.46; the exact interval is the 6th and 40th of the 45 Walsh averages
    (qsignrank(0.025, 9) = 6), at the achieved level 1 - 2 P(T+ <= 5) = 1 - 20/512 = 96.1 %.

    >>> x = np.array([1.83, 0.50, 1.62, 2.48, 1.68, 1.88, 1.55, 3.06, 1.30])
    >>> y = np.array([0.878, 0.647, 0.598, 2.05, 1.06, 1.29, 1.06, 3.14, 1.29])
    >>> h = hodges_lehmann(x - y)
    >>> round(h.estimate, 3), round(h.ci_low, 4), round(h.ci_high, 4), h.method, round(h.conf_level, 3)
    (0.46, 0.01, 0.786, 'exact', 0.961)
    """
    nz = _nonzero(d)
    n = nz.size
    zeros = np.asarray(d).size - n
    if n == 0:
        return HodgesLehmann(0.0, np.nan, np.nan, "none", np.nan, 0)
    # Walsh averages as distinct values and counts: n = 10,000 participants would be 50 M averages
    walsh, cum = walsh_distinct(nz)
    cum = np.cumsum(cum)
    total = int(cum[-1])
    mid_lo, mid_hi = _walsh_at(walsh, cum, (total - 1) // 2), _walsh_at(walsh, cum, total // 2)
    est = mid_lo if total % 2 else float(np.mean([mid_lo, mid_hi]))  # as numpy's median of the averages
    alpha = 1.0 - ci
    ties = np.unique(np.round(np.abs(nz), _DECIMALS)).size < n
    if n < WILCOXON_EXACT_BELOW_N and not ties and zeros == 0:
        cdf = signed_rank_cdf(n)
        qu = int(np.searchsorted(cdf, alpha / 2.0 * (1 - 64 * np.finfo(float).eps)))  # R's qsignrank
        qu = max(qu, 1)
        ql = n * (n + 1) // 2 - qu
        achieved = 2.0 * cdf[qu - 1]
        return HodgesLehmann(est, _walsh_at(walsh, cum, qu - 1), _walsh_at(walsh, cum, ql), "exact",
                             float(1.0 - achieved), n)
    values, counts = np.unique(nz, return_counts=True)
    # R widens the level until the ends lie inside [min d, max d] (possible only with very few blocks).
    while alpha < 1.0:
        zq = float(stats.norm.isf(alpha / 2.0))
        if _z_shifted(values, counts, values[0]) >= zq and _z_shifted(values, counts, values[-1]) <= -zq:
            break
        alpha *= 2.0
    if alpha >= 1.0:
        return HodgesLehmann(est, np.nan, np.nan, "normal approximation", np.nan, n)
    return HodgesLehmann(est, _first_below(walsh, values, counts, zq), _first_below(walsh, values, counts, -zq),
                         "normal approximation",
                         1.0 - alpha, n)


# --- statistics as functions of participant weights (for the cluster bootstrap) --------------------
# Each statistic below depends on a resample only through per-participant totals (rank sums, counts of
# each distinct difference), so a resample costs a (P x something) matrix product, never a copy of its rows.


def _row_weights(blocks: RankBlocks) -> tuple[int, np.ndarray]:
    """Number of clusters (participants) and each block's cluster index."""
    _, inverse = participant_index(blocks.participants)
    return int(inverse.max()) + 1 if inverse.size else 0, inverse


def _per_cluster(cluster: np.ndarray, n_clusters: int, values: np.ndarray) -> np.ndarray:
    """(P, ...) sums of ``values`` (rows = blocks) per cluster."""
    return cluster_totals(cluster, n_clusters, values)


def _tie_sums(r: np.ndarray) -> np.ndarray:
    """Per block (row) the sum of t^3 - t over its tied groups: sum over its values of (t_i^2 - 1), t_i the
    size of value i's group (integers, so exact whatever the order)."""
    r = np.round(r, _DECIMALS)
    t = (r[:, :, None] == r[:, None, :]).sum(axis=2).astype(float)
    return (t * t - 1.0).sum(axis=1)


def _kendall_w_stat(blocks: RankBlocks, cluster: np.ndarray, n_clusters: int) -> ClusterSums:
    r = blocks.ranks
    n, k = r.shape
    # per cluster: blocks, rank sums (k), tie sums
    sums = _per_cluster(cluster, n_clusters, np.column_stack([np.ones(n), r, _tie_sums(r)]))

    def of(s: np.ndarray) -> np.ndarray:
        nb, rank_sums, ties = s[:, 0], s[:, 1:1 + k], s[:, 1 + k]
        chi2 = 12.0 / (nb * k * (k + 1)) * (rank_sums ** 2).sum(axis=1) - 3.0 * nb * (k + 1)
        c = 1.0 - ties / (nb * k * (k * k - 1))
        safe = c > 1e-12
        chi2 = np.where(safe, np.maximum(chi2 / np.where(safe, c, 1.0), 0.0), 0.0)
        return chi2 / (nb * (k - 1))
    return ClusterSums(sums, of)


def _distinct_counts(d: np.ndarray, cluster: np.ndarray, n_clusters: int, key: np.ndarray):
    """Distinct values of ``key`` over the non-zero differences and their (P, U) counts per cluster."""
    keep = np.round(d, _DECIMALS) != 0
    u, which = np.unique(np.round(key[keep], _DECIMALS), return_inverse=True)
    onehot = np.zeros((int(keep.sum()), u.size))
    onehot[np.arange(onehot.shape[0]), which] = 1.0
    return u, keep, onehot, _per_cluster(cluster[keep], n_clusters, onehot)


def _rank_biserial_stat(d: np.ndarray, cluster: np.ndarray, n_clusters: int) -> ClusterSums:
    _, keep, onehot, counts = _distinct_counts(d, cluster, n_clusters, np.abs(d))
    positive = _per_cluster(cluster[keep], n_clusters, onehot * (d[keep] > 0)[:, None])
    u = counts.shape[1]

    def of(s: np.ndarray) -> np.ndarray:
        cnt = s[:, :u]                                      # (R, U) resampled count of each |d|
        avg_rank = np.cumsum(cnt, axis=1) - cnt + (cnt + 1.0) / 2.0
        v = (s[:, u:] * avg_rank).sum(axis=1)
        nn = cnt.sum(axis=1)
        total = nn * (nn + 1.0) / 2.0
        return np.where(nn > 0, (2.0 * v - np.where(nn > 0, total, 1.0)) / np.where(nn > 0, total, 1.0), 0.0)
    return ClusterSums(np.concatenate([counts, positive], axis=1), of)


def _hodges_lehmann_stat(d: np.ndarray, cluster: np.ndarray, n_clusters: int) -> ClusterSums:
    # A resample's Walsh averages depend only on how often each distinct difference occurs in it: values
    # e_l and e_m (l < m) give n_l n_m averages (e_l + e_m)/2, and e_l with itself n_l (n_l + 1)/2.
    e, _, _, counts = _distinct_counts(d, cluster, n_clusters, d)
    li, mi = np.triu_indices(e.size)
    averages = np.round((e[li] + e[mi]) / 2.0, _DECIMALS)
    order = np.argsort(averages, kind="stable")
    walsh, li, mi = averages[order], li[order], mi[order]
    same = li == mi
    step = max(1, _WALSH_CELLS // max(walsh.size, 1))

    def of(s: np.ndarray) -> np.ndarray:
        out = np.zeros(len(s))
        if walsh.size == 0:
            return out
        for start in range(0, len(s), step):
            n = s[start:start + step]                        # (R, U) resampled count of each difference
            pw = np.where(same, n[:, li] * (n[:, li] + 1.0) / 2.0, n[:, li] * n[:, mi])
            cum = np.cumsum(pw, axis=1)
            total = cum[:, -1]
            lo = np.floor((total + 1.0) / 2.0)              # the middle one or two positions (1-based)
            hi = np.ceil((total + 1.0) / 2.0)
            a = np.minimum((cum < lo[:, None]).sum(axis=1), walsh.size - 1)
            b = np.minimum((cum < hi[:, None]).sum(axis=1), walsh.size - 1)
            out[start:start + len(n)] = np.where(total > 0, (walsh[a] + walsh[b]) / 2.0, 0.0)
        return out
    return ClusterSums(counts, of)


def _bootstrap_name(method: str) -> str:
    """'BCa' -> 'BCa bootstrap'; 'percentile (BCa undefined)' -> 'percentile bootstrap (BCa undefined)'."""
    if method == "none":
        return method
    head, _, tail = method.partition(" (")
    return f"{head} bootstrap" + (f" ({tail}" if tail else "")


def effect_sizes(blocks: RankBlocks, *, n_boot: int = 2000, ci: float = 0.95, seed: int = 0,
                 interval: str = "bca", control: str | None = None) -> EffectSizes:
    """Kendall's W and, per pair (all pairs, or the k-1 against ``control``), r_rb and Hodges-Lehmann, each
    with its interval (see the module docstring). Pairs are oriented as the Wilcoxon table's: a - b.

    ``kendall_w`` columns: estimate, ci_low, ci_high, interval. ``pairs`` columns: a, b, rank_biserial,
    rb_ci_low, rb_ci_high, rb_interval, hodges_lehmann, hl_ci_low, hl_ci_high, hl_interval, hl_conf_level.
    """
    n_clusters, cluster = _row_weights(blocks)
    todo = pairs(blocks.conditions, control)
    diffs = [blocks.values[:, i] - blocks.values[:, j] for i, j in todo]
    boot_hl = blocks.block != "participant"
    # One set of resamples for every statistic: W, then r_rb per pair, then (trial blocks) HL per pair.
    parts = [_kendall_w_stat(blocks, cluster, n_clusters)]
    parts += [_rank_biserial_stat(d, cluster, n_clusters) for d in diffs]
    parts += [_hodges_lehmann_stat(d, cluster, n_clusters) for d in diffs] if boot_hl else []
    res = cluster_bootstrap(ClusterSums.stack(parts), n_clusters, n_boot=n_boot, ci=ci,
                            seed=seed, method=interval)
    w_table = pd.DataFrame([{"estimate": res.estimate[0], "ci_low": res.low[0], "ci_high": res.high[0],
                             "interval": _bootstrap_name(res.method[0])}])
    rows = []
    for p, ((i, j), d) in enumerate(zip(todo, diffs)):
        rb = 1 + p
        row = {"a": blocks.conditions[i], "b": blocks.conditions[j], "rank_biserial": res.estimate[rb],
               "rb_ci_low": res.low[rb], "rb_ci_high": res.high[rb], "rb_interval": _bootstrap_name(res.method[rb])}
        if boot_hl:
            hl = 1 + len(todo) + p
            row.update(hodges_lehmann=res.estimate[hl], hl_ci_low=res.low[hl], hl_ci_high=res.high[hl],
                       hl_interval=_bootstrap_name(res.method[hl]), hl_conf_level=ci)
        else:
            h = hodges_lehmann(d, ci=ci)
            row.update(hodges_lehmann=h.estimate, hl_ci_low=h.ci_low, hl_ci_high=h.ci_high, hl_interval=h.method,
                       hl_conf_level=h.conf_level)
        rows.append(row)
    cols = ["a", "b", "rank_biserial", "rb_ci_low", "rb_ci_high", "rb_interval", "hodges_lehmann", "hl_ci_low",
            "hl_ci_high", "hl_interval", "hl_conf_level"]
    return EffectSizes(kendall_w=w_table, pairs=pd.DataFrame(rows, columns=cols), interval=interval,
                       n_boot=n_boot, ci=ci, seed=seed)
