"""Post-hoc pairwise comparisons after a Friedman test.

* Nemenyi (single-step, Demsar 2006): z = |Rbar_a - Rbar_b| / sqrt(k(k+1)/(6n)); the adjusted p is the
  studentized-range tail P(Q_{k,inf} > z sqrt(2)), and the critical difference is
  CD = q_alpha / sqrt(2) * sqrt(k(k+1)/(6n)), q_alpha the studentized-range quantile. This is the test the
  critical-difference diagram draws.
* Pairwise Wilcoxon signed-rank tests on the within-block ranks (a trial's average ranks, or a
  participant's mean of them), so the tie coding cannot matter, Holm-adjusted, with R's ``wilcox.test``
  defaults: zero differences are dropped (Wilcoxon's method); the exact null distribution is used only
  when fewer than 50 non-zero differences remain and there were neither ties nor zeros, otherwise the
  normal approximation with tie correction and continuity correction (scipy's default differs: it keeps
  the exact test when zeros were dropped and has no continuity correction). The method actually used is
  reported per pair.
* Conover's Friedman post-hoc (Conover 1999): t = |R_a - R_b| / sqrt(2 (n A - sum R_j^2) / ((n-1)(k-1)))
  with rank sums R, A the sum of all squared ranks, t distribution with (n-1)(k-1) df, Holm-adjusted.

Every function takes an (n blocks, k conditions) matrix and the condition names and returns a DataFrame
with columns a, b, statistic, p, p_adjusted (and extras).
"""
from __future__ import annotations

from functools import lru_cache
from itertools import combinations

import numpy as np
import pandas as pd
from scipy import stats

from results_analysis.adjust import ADJUSTMENT_NAMES, adjust_pvalues
from results_analysis.ranks import within_block_ranks

#: The exact Wilcoxon distribution is used for fewer than this many non-zero differences (R: ``n < 50``).
WILCOXON_EXACT_BELOW_N = 50


def holm(p: np.ndarray | list[float]) -> np.ndarray:
    """Holm's step-down adjustment (family-wise error), in the input order (see :mod:`results_analysis.adjust`).

    >>> holm([0.01, 0.04, 0.03]).round(3).tolist()
    [0.03, 0.06, 0.06]
    """
    return adjust_pvalues(p, "holm")


def pairs(conditions: list[str], control: str | None = None) -> list[tuple[int, int]]:
    """Column index pairs to compare: all k(k-1)/2 pairs, or the k-1 pairs (control, other) when a control
    condition is named ("ours vs each baseline"), control first.

    >>> pairs(["A", "B", "C"]), pairs(["A", "B", "C"], control="B")
    ([(0, 1), (0, 2), (1, 2)], [(1, 0), (1, 2)])
    """
    if control is None:
        return list(combinations(range(len(conditions)), 2))
    if control not in conditions:
        raise KeyError(f"control condition {control!r} is not one of {list(conditions)}")
    c = conditions.index(control)
    return [(c, j) for j in range(len(conditions)) if j != c]


def nemenyi_q_alpha(k: int, alpha: float = 0.05) -> float:
    """Demsar's q_alpha: the studentized-range quantile for k groups and infinite df, over sqrt(2).

    >>> round(nemenyi_q_alpha(4, 0.05), 3)
    2.569
    """
    if k < 2:
        raise ValueError("the Nemenyi test needs at least 2 conditions")
    return _q_alpha(int(k), float(alpha))


@lru_cache(maxsize=64)
def _q_alpha(k: int, alpha: float) -> float:
    """The studentized-range quantile of :func:`nemenyi_q_alpha` (a numerical integration of some 10 ms, asked
    for twice per criterion with the same k and alpha): a pure function of two numbers, so kept."""
    return float(stats.studentized_range.ppf(1.0 - alpha, k, np.inf) / np.sqrt(2.0))


def critical_difference(k: int, n: int, alpha: float = 0.05) -> float:
    """Nemenyi critical difference of mean ranks: q_alpha * sqrt(k(k+1)/(6n)).

    >>> round(critical_difference(4, 14, 0.05), 2)
    1.25
    """
    return nemenyi_q_alpha(k, alpha) * float(np.sqrt(k * (k + 1) / (6.0 * n)))


def _matrix(data: np.ndarray | pd.DataFrame, conditions: list[str] | None) -> tuple[np.ndarray, list[str]]:
    """An (n blocks, k) array and the condition names, from an array + names or a wide DataFrame
    (rows = blocks, columns = conditions; rows with a missing value are dropped, listwise)."""
    if isinstance(data, pd.DataFrame):
        if conditions is not None:  # pick the columns by name: labelling them in place would mislabel them
            missing = [c for c in conditions if c not in data.columns]
            if missing:
                raise KeyError(f"conditions {missing} are not columns of the DataFrame ({list(data.columns)})")
            data = data[list(conditions)]
        wide = data.dropna(axis=0, how="any")
        return wide.to_numpy(dtype=float), [str(c) for c in wide.columns]
    if conditions is None:
        raise ValueError("pass the condition names with an array (or give a DataFrame with named columns)")
    return np.asarray(data, dtype=float), list(conditions)


def nemenyi(ranks: np.ndarray | pd.DataFrame, conditions: list[str] | None = None, *,
            alpha: float = 0.05) -> pd.DataFrame:
    """Nemenyi single-step comparisons of mean ranks (``ranks``: within-block average ranks, or a wide
    DataFrame of block values, which are ranked within each row first).

    Columns: a, b, mean_rank_a, mean_rank_b, statistic (z), p (unadjusted two-sided normal), p_adjusted
    (single-step studentized range), significant (|difference| > CD, equivalently p_adjusted < alpha).
    """
    frame = isinstance(ranks, pd.DataFrame)
    ranks, conditions = _matrix(ranks, conditions)
    if frame:
        ranks = within_block_ranks(ranks)
    n, k = ranks.shape
    mean = ranks.mean(axis=0)
    se = np.sqrt(k * (k + 1) / (6.0 * n))
    cd = critical_difference(k, n, alpha)
    rows = []
    for i, j in combinations(range(k), 2):
        diff = abs(mean[i] - mean[j])
        z = diff / se
        rows.append({"a": conditions[i], "b": conditions[j], "mean_rank_a": mean[i], "mean_rank_b": mean[j],
                     "difference": diff, "statistic": z, "p": float(2 * stats.norm.sf(z)),
                     "p_adjusted": float(stats.studentized_range.sf(z * np.sqrt(2.0), k, np.inf)),
                     "significant": bool(diff > cd)})
    out = pd.DataFrame(rows)
    out.attrs.update(method="nemenyi", critical_difference=cd, alpha=alpha)
    return out


def wilcoxon_holm(values: np.ndarray | pd.DataFrame, conditions: list[str] | None = None, *,
                  adjust: str = "holm", control: str | None = None) -> pd.DataFrame:
    """Pairwise Wilcoxon signed-rank tests on paired block values, Holm-adjusted (or ``adjust='bh'`` /
    ``'bonferroni'``, see :mod:`results_analysis.adjust`) over the pairs tested: all pairs, or with
    ``control`` only the k-1 pairs (control, other), adjusted over k-1.

    An array (with the condition names) is tested as given: pass within-block ranks for a rank analysis,
    or any paired measurements. A wide DataFrame of block values is ranked within each row first (average
    ranks), as :func:`nemenyi` and :func:`conover` do, so answers with ties written 1,1,3 or 1.5,1.5,3 give
    the same result.

    Columns: a, b, statistic (V: sum of the ranks of positive differences a - b, as R reports),
    n_nonzero, zeros_dropped, method ('exact' or 'normal approximation'), continuity_correction,
    rank_biserial (matched-pairs effect size, positive when a has the larger values), p, p_adjusted,
    adjustment (the adjustment's name).
    """
    frame = isinstance(values, pd.DataFrame)
    values, conditions = _matrix(values, conditions)
    if frame:
        values = within_block_ranks(values)
    rows = []
    for i, j in pairs(conditions, control):
        # Rounded: participants' mean ranks differ by float noise (2/3 computed two ways), which must
        # neither break a tie between |d| values nor leave a zero difference.
        d = np.round(values[:, i] - values[:, j], 10)
        nz = d[d != 0]
        n_nz = nz.size
        row = {"a": conditions[i], "b": conditions[j], "n_nonzero": n_nz, "zeros_dropped": int(d.size - n_nz)}
        if n_nz == 0:
            row.update(statistic=0.0, method="none (all differences zero)", continuity_correction=False,
                       rank_biserial=0.0, p=1.0)
        else:
            r = stats.rankdata(np.abs(nz))
            v = float(r[nz > 0].sum())
            total = n_nz * (n_nz + 1) / 2.0
            ties = np.unique(r).size < n_nz
            # R also falls back to the normal approximation when zeros were dropped, not only on ties.
            exact = n_nz < WILCOXON_EXACT_BELOW_N and not ties and row["zeros_dropped"] == 0
            res = stats.wilcoxon(nz, zero_method="wilcox", correction=not exact,
                                 method="exact" if exact else "asymptotic")
            row.update(statistic=v, method="exact" if exact else "normal approximation",
                       continuity_correction=not exact, rank_biserial=float((2 * v - total) / total),
                       p=float(res.pvalue))
        rows.append(row)
    out = pd.DataFrame(rows)
    out["p_adjusted"] = adjust_pvalues(out["p"].to_numpy(), adjust)
    out["adjustment"] = ADJUSTMENT_NAMES[adjust]
    out = out[["a", "b", "statistic", "n_nonzero", "zeros_dropped", "method", "continuity_correction",
               "rank_biserial", "p", "p_adjusted", "adjustment"]]
    out.attrs.update(method="wilcoxon_holm", zero_method="wilcox (zero differences dropped)", adjust=adjust,
                     control=control)
    return out


def conover(ranks: np.ndarray | pd.DataFrame, conditions: list[str] | None = None, *, adjust: str = "holm",
            control: str | None = None) -> pd.DataFrame:
    """Conover's all-pairs post-hoc for the Friedman test (t distribution), Holm-adjusted (or ``adjust``; with
    ``control`` only the k-1 pairs against it, adjusted over k-1).

    ``ranks`` are within-block average ranks, or a wide DataFrame of block values (ranked within each row
    first). Columns: a, b, statistic (t), df, p, p_adjusted.
    """
    frame = isinstance(ranks, pd.DataFrame)
    ranks, conditions = _matrix(ranks, conditions)
    if frame:
        ranks = within_block_ranks(ranks)
    n, k = ranks.shape
    rank_sums = ranks.sum(axis=0)
    a1 = float(np.sum(ranks ** 2))
    dfree = (n - 1) * (k - 1)
    var = 2.0 * (n * a1 - float(np.sum(rank_sums ** 2))) / dfree if dfree > 0 else 0.0
    rows = []
    for i, j in pairs(conditions, control):
        diff = abs(rank_sums[i] - rank_sums[j])
        if var <= 1e-12:
            t, p = (float("inf"), 0.0) if diff > 0 else (0.0, 1.0)
        else:
            t = diff / np.sqrt(var)
            p = float(2 * stats.t.sf(t, dfree))
        rows.append({"a": conditions[i], "b": conditions[j], "statistic": float(t), "df": dfree, "p": p})
    out = pd.DataFrame(rows)
    out["p_adjusted"] = adjust_pvalues(out["p"].to_numpy(), adjust)
    out["adjustment"] = ADJUSTMENT_NAMES[adjust]
    out.attrs.update(method="conover", adjust=adjust, control=control)
    return out


def posthoc_table(data: pd.DataFrame, method: str = "nemenyi", **kwargs) -> pd.DataFrame:
    """Pingouin-style entry point: a wide frame (rows = blocks, columns = conditions) in, a table out.

    >>> import pandas as pd
    >>> wide = pd.DataFrame({"A": [1, 1, 1, 1, 2], "B": [2, 2, 3, 2, 1], "C": [3, 3, 2, 3, 3]})
    >>> posthoc_table(wide, "nemenyi")[["a", "b"]].values.tolist()
    [['A', 'B'], ['A', 'C'], ['B', 'C']]
    """
    wide = data.dropna(axis=0, how="any")
    values = wide.to_numpy(dtype=float)
    names = [str(c) for c in wide.columns]
    if method == "nemenyi":
        return nemenyi(within_block_ranks(values), names, **kwargs)
    if method == "wilcoxon_holm":
        return wilcoxon_holm(within_block_ranks(values), names)
    if method == "conover":
        return conover(within_block_ranks(values), names)
    raise ValueError(f"unknown post-hoc method {method!r}: nemenyi, wilcoxon_holm or conover")
