"""Friedman test with tie correction, Kendall's W and the Iman-Davenport F.

chi2 = [12 / (n k (k+1)) * sum_j R_j^2 - 3 n (k+1)] / C with R_j the rank sums over the n blocks and
C = 1 - sum(t^3 - t) / (n k (k^2 - 1)) the tie correction (t: sizes of tied groups within a block), as in
R's ``friedman.test``, scipy and pingouin. Kendall's W = chi2 / (n (k-1)). Iman-Davenport
F = (n-1) chi2 / (n (k-1) - chi2) with df (k-1, (k-1)(n-1)).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import pandas as pd
from scipy import stats

from results_analysis.ranks import _half_steps, tie_sizes, ties, within_block_ranks


@dataclass(frozen=True)
class FriedmanResult:
    """One Friedman test. ``mean_rank`` is in the column order of the input."""

    n_blocks: int
    k: int
    chi2: float
    df: int
    p: float
    kendall_w: float
    iman_davenport_f: float
    iman_davenport_df1: int
    iman_davenport_df2: int
    iman_davenport_p: float
    tie_correction: float
    mean_rank: tuple[float, ...]

    def as_dict(self) -> dict:
        return asdict(self)


def friedman_ranks(ranks: np.ndarray, *, tie_correction: bool = True) -> FriedmanResult:
    """Friedman test on an (n blocks, k conditions) matrix of within-block (average) ranks.

    >>> r = friedman_ranks(np.array([[1, 2, 3]] * 4 + [[2, 1, 3]]))
    >>> round(r.chi2, 3), r.df, round(r.kendall_w, 3)
    (8.4, 2, 0.84)
    """
    ranks = np.asarray(ranks, dtype=float)
    n, k = ranks.shape
    if k < 2 or n < 1:
        raise ValueError(f"a Friedman test needs at least 1 block and 2 conditions, got {n} x {k}")
    rank_sums = ranks.sum(axis=0)
    chi2 = 12.0 / (n * k * (k + 1)) * float(np.sum(rank_sums ** 2)) - 3.0 * n * (k + 1)
    c = 1.0
    if tie_correction:
        c = 1.0 - _tie_sum(ranks) / (n * k * (k * k - 1))
    if c <= 1e-12:
        chi2 = 0.0  # every block ties every condition: no evidence either way
    else:
        chi2 = max(chi2 / c, 0.0)
    dfree = k - 1
    p = float(stats.chi2.sf(chi2, dfree))
    w = chi2 / (n * (k - 1))
    denom = n * (k - 1) - chi2
    df1, df2 = k - 1, (k - 1) * (n - 1)
    if denom <= 1e-12 * n * k:
        f, pf = float("inf"), 0.0
    else:
        f = (n - 1) * chi2 / denom
        pf = float(stats.f.sf(f, df1, df2)) if df2 > 0 else float("nan")
    return FriedmanResult(n_blocks=n, k=k, chi2=float(chi2), df=dfree, p=p, kendall_w=float(w),
                          iman_davenport_f=float(f), iman_davenport_df1=df1, iman_davenport_df2=df2,
                          iman_davenport_p=pf, tie_correction=float(c),
                          mean_rank=tuple(float(v) for v in ranks.mean(axis=0)))


def _tie_sum(ranks: np.ndarray) -> float:
    """sum over blocks and tied groups of t^3 - t, from average ranks (tied values share a rank)."""
    if ranks.shape[1] <= 6 and _half_steps(ranks):
        # each of a group's t cells ties with t cells: sum over cells of t^2 - 1 is sum over groups of t^3 - t,
        # whole numbers (exact); for half-step ranks, ties are equal values, so the groups are the runs below
        t = tie_sizes(ranks)
        return float((t * t - 1).sum())
    s = np.sort(ranks, axis=1)
    n, k = s.shape
    # Run lengths of equal values per row, vectorized over rows.
    starts = np.ones((n, k), dtype=bool)
    starts[:, 1:] = ~ties(s[:, 1:], s[:, :-1])
    run_id = np.cumsum(starts, axis=1) - 1 + (np.arange(n) * k)[:, None]
    t = np.bincount(run_id.ravel(), minlength=n * k).astype(float)
    return float(np.sum(t ** 3 - t))


def kendall_w(ranks: np.ndarray, *, tie_correction: bool = True) -> float:
    """Kendall's coefficient of concordance W = chi2_F / (n (k-1)) of a blocks x conditions rank matrix."""
    return friedman_ranks(ranks, tie_correction=tie_correction).kendall_w


def friedman(data: pd.DataFrame, dv: str | None = None, within: str | None = None,
             subject: str | None = None, *, tie_correction: bool = True) -> pd.DataFrame:
    """Friedman test, pingouin-style: a wide frame (rows = blocks, columns = conditions) or long format.

    Values are ranked within each block with average ranks (ties corrected). Returns one row with
    n_blocks, k, chi2, df, p, kendall_w, iman_davenport_f, iman_davenport_df1/df2, iman_davenport_p.
    Unlike pingouin's long form, a subject with several values per condition is an error, not averaged.

    >>> import pandas as pd
    >>> wide = pd.DataFrame({"before": [72, 96, 88, 92, 74, 76, 82],
    ...                      "after": [120, 120, 132, 120, 101, 96, 112],
    ...                      "later": [76, 95, 104, 96, 84, 72, 76]})
    >>> round(float(friedman(wide)["chi2"].iloc[0]), 4)
    10.5714
    """
    if dv is not None:
        if within is None or subject is None:
            raise ValueError("long format needs dv, within and subject")
        if data.duplicated([subject, within]).any():
            raise ValueError(f"several values of {dv!r} for one {subject!r} x {within!r}: aggregate first")
        wide = data.pivot(index=subject, columns=within, values=dv).dropna(axis=0, how="any")
    else:
        wide = data.dropna(axis=0, how="any")
    res = friedman_ranks(within_block_ranks(wide.to_numpy(dtype=float)), tie_correction=tie_correction)
    row = res.as_dict()
    row.pop("mean_rank")
    out = pd.DataFrame([row], index=["Friedman"])
    out.attrs["mean_rank"] = dict(zip(map(str, wide.columns), res.mean_rank))
    return out
