"""Inter-rater agreement per stimulus: Kendall's coefficient of concordance W across the participants who
ranked a stimulus, with its chi-squared test, and a summary over the stimuli.

For one stimulus and criterion the m raters are the participants who ranked it (a participant who ranked
it more than once contributes their mean within-trial rank per condition, re-ranked), the k objects the
conditions. Kendall & Babington Smith (1939), with the correction for ties (Kendall 1948):

    W = 12 S / (m^2 (k^3 - k) - m sum T),   S = sum_j (R_j - m (k+1)/2)^2,   T = sum over tied groups t^3 - t

with R_j the rank sums; chi2 = m (k-1) W on k-1 degrees of freedom (identical to the tie-corrected
Friedman statistic over the raters). W = 1: every rater ordered the conditions the same way; W = 0: no
agreement. The per-stimulus p-values are adjusted over the stimuli of a criterion
(:mod:`results_analysis.adjust`).

The summary per criterion: the number of stimuli with at least two raters, the median, mean, minimum and
maximum of W, the mean number of raters and how many stimuli show significant concordance.
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

from results_analysis.adjust import ADJUSTMENT_NAMES, adjust_pvalues
from results_analysis.friedman import friedman_ranks
from results_analysis.ranks import CriterionTable, rank_blocks_by, split_table, text_levels

AGREEMENT_COLUMNS = ["criterion", "stimulus", "n_raters", "kendall_w", "chi2", "df", "p", "p_adjusted",
                     "adjustment"]


def stimulus_agreement(df: pd.DataFrame, *, conditions: list[str], criteria: Sequence[str],
                       adjust: str = "holm") -> pd.DataFrame:
    """One row per criterion and stimulus of a validated, exclusion-applied tidy frame (see module docstring).

    Columns: criterion, stimulus, n_raters, kendall_w, chi2, df, p, p_adjusted, adjustment (NaN statistics
    for a stimulus with fewer than two raters).

    >>> from results_analysis.simulate import simulate_results
    >>> df = simulate_results(6, 2, seed=1, n_practice=0, n_attention=0)
    >>> t = stimulus_agreement(df, conditions=["FaceCapGes", "DiffSHEG", "CaMN"], criteria=["realism"])
    >>> t[["stimulus", "n_raters"]].values.tolist()
    [['clip1', 6], ['clip2', 6]]
    """
    return split_agreement(df, None, conditions=conditions, criteria=criteria, adjust=adjust)


def split_agreement(df: pd.DataFrame, tables: dict[str, CriterionTable] | None, *, conditions: list[str],
                    criteria: Sequence[str], adjust: str = "holm") -> pd.DataFrame:
    """:func:`stimulus_agreement`, splitting each criterion's ``tables`` entry (from
    :func:`results_analysis.ranks.criterion_table`) when given."""
    k = len(conditions)
    rows = []
    # one trials x conditions matrix per criterion (shared with the rest of the analysis within
    # shared_trial_tables, or given), split by stimulus (sorted); the stimuli factorized once for every criterion
    stimuli = text_levels(df["stimulus"])
    for crit in criteria:
        mine = df["criterion"].to_numpy(dtype=object) == crit if tables is None else tables[crit].rows
        rated = stimuli.categories[np.unique(stimuli.codes[mine])]
        first = len(rows)
        split = rank_blocks_by(df, crit, stimuli, block="participant", conditions=conditions) if tables is None \
            else split_table(df, crit, tables[crit], stimuli, block="participant", conditions=conditions)
        for stim, (b, _) in split.items():
            if stim not in rated:  # a stimulus that was never rated on this criterion has no row
                continue
            row = {"criterion": crit, "stimulus": stim, "n_raters": b.n, "df": k - 1}
            if b.n >= 2:
                fr = friedman_ranks(b.ranks)
                row.update(kendall_w=fr.kendall_w, chi2=fr.chi2, p=fr.p)
            else:
                row.update(kendall_w=np.nan, chi2=np.nan, p=np.nan)
            rows.append(row)
        block = pd.DataFrame(rows[first:])
        if len(block):
            p = block["p"].to_numpy(dtype=float)
            adj = np.full(p.size, np.nan)
            ok = np.isfinite(p)
            adj[ok] = adjust_pvalues(p[ok], adjust)
            for r, v in zip(rows[first:], adj):
                r["p_adjusted"], r["adjustment"] = float(v), ADJUSTMENT_NAMES[adjust]
    return pd.DataFrame(rows, columns=AGREEMENT_COLUMNS)


def agreement_summary(table: pd.DataFrame, *, alpha: float = 0.05) -> pd.DataFrame:
    """Per criterion: n_stimuli (with two or more raters), median_w, mean_w, min_w, max_w, mean_raters,
    n_significant (adjusted p < alpha) of a :func:`stimulus_agreement` table.

    >>> t = pd.DataFrame({"criterion": "realism", "stimulus": ["a", "b", "c"], "n_raters": [4, 6, 1],
    ...                   "kendall_w": [0.2, 0.6, np.nan], "p_adjusted": [0.3, 0.01, np.nan]})
    >>> agreement_summary(t)[["n_stimuli", "median_w", "n_significant"]].values.tolist()
    [[2.0, 0.4, 1.0]]
    """
    rows = []
    for crit, sub in table.groupby("criterion", sort=False):
        ok = sub[np.isfinite(sub["kendall_w"].to_numpy(dtype=float))]
        w = ok["kendall_w"].to_numpy(dtype=float)
        rows.append({"criterion": crit, "n_stimuli": int(len(ok)),
                     "median_w": float(np.median(w)) if w.size else np.nan,
                     "mean_w": float(w.mean()) if w.size else np.nan,
                     "min_w": float(w.min()) if w.size else np.nan, "max_w": float(w.max()) if w.size else np.nan,
                     "mean_raters": float(ok["n_raters"].mean()) if len(ok) else np.nan,
                     "n_significant": int((ok["p_adjusted"] < alpha).sum())})
    return pd.DataFrame(rows, columns=["criterion", "n_stimuli", "median_w", "mean_w", "min_w", "max_w",
                                       "mean_raters", "n_significant"])
