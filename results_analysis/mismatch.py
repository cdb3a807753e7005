"""Speech-mismatch blocks: how often the motion with its own speech is preferred (GENEA 2022's appropriateness).

A mismatch trial shows one condition twice: one slot plays the motion made for the trial's speech
(``matched`` = 1), the other a motion made for another clip of the same speaker (``matched`` = 0). The trial's
*score* is 1 when the matched slot is preferred (any positive level for it), 1/2 for "equal" and 0 when the
mismatched one is preferred. Chance is 0.5.

* :func:`matched_preference` — per condition the matched-preference rate (the mean score: ties count half),
  the counts (matched preferred, equal, mismatched preferred), a percentile interval from a participant
  bootstrap (participants resampled whole, seeded; the rate of a resample is its total score over its total
  trials), and a two-sided exact binomial test of "matched and mismatched equally often preferred" on the
  trials with a preference (ties carry no direction, so the sign test leaves them out). The binomial test
  treats trials as independent, as GENEA does; the participant-bootstrap interval is the evidence that
  respects repeated measures (it excludes 0.5 when the effect holds across participants).
* :func:`compare_conditions` — every pair of conditions: the difference of their rates with a participant
  bootstrap interval and two-sided bootstrap p-value (twice the smaller share of resampled differences on either
  side of 0), and Barnard's exact test (``scipy.stats.barnard_exact``, two-sided, pooled Wald statistic) on the
  2x2 table [[matched preferred, not] for each condition]. Ties enter that table split: half of a
  condition's ties count as "matched preferred" and half as "not"; with an odd number of ties the odd one counts
  as "not" (rounding down the matched side, so a split never adds evidence for the matched motion).
  ``ties='drop'`` leaves ties out of the table instead. Both families of p-values are Holm-adjusted (or another
  :data:`results_analysis.adjust.ADJUSTMENTS` method) over the pairs.
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd
from scipy import stats

from results_analysis.adjust import ADJUSTMENT_NAMES, adjust_pvalues
from results_analysis.descriptives import bootstrap_weights
from results_analysis.errors import AnalysisInputError
from results_analysis.paradigms import preference_trials

#: How ties enter Barnard's 2x2 table.
BARNARD_TIES = ("split", "drop")


def trial_scores(data: pd.DataFrame, criterion: str | None = None) -> pd.DataFrame:
    """One row per mismatch trial: participant, condition, score (1 matched preferred, 0.5 equal, 0 mismatched
    preferred), pref_matched (-2..2, for the matched slot).

    >>> t = pd.DataFrame({"participant": "P1", "trial_index": 0, "stimulus": "s", "criterion": "c",
    ...                   "condition": ["A", "A"], "slot": [0, 1], "preference": [-2.0, 2.0], "matched": [0, 1],
    ...                   "paradigm": "mismatch"})
    >>> trial_scores(t)[["condition", "score", "pref_matched"]].values.tolist()
    [['A', 1.0, 2.0]]
    """
    if criterion is not None:
        data = data[data["criterion"] == criterion]
    t = preference_trials(data)
    if t["a_matched"].isna().any():
        raise AnalysisInputError(data.attrs.get("source"), "column 'matched'",
                                 "mismatch rows need matched = 1 or 0 on every row")
    pm = np.where(t["a_matched"].to_numpy() == 1, t["pref_a"].to_numpy(), -t["pref_a"].to_numpy())
    return pd.DataFrame({"participant": t["participant"].astype(str).to_numpy(), "trial_index": t["trial_index"],
                         "criterion": t["criterion"].to_numpy(), "condition": t["a"].to_numpy(),
                         "score": np.where(pm > 0, 1.0, np.where(pm < 0, 0.0, 0.5)), "pref_matched": pm})


def _participant_sums(scores: pd.DataFrame, conds: list[str]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Participants, (P, k) score sums and (P, k) trial counts."""
    ids, inverse = np.unique(scores["participant"].to_numpy(), return_inverse=True)
    idx = {c: i for i, c in enumerate(conds)}
    ci = scores["condition"].map(idx).to_numpy()
    s = np.zeros((ids.size, len(conds)))
    n = np.zeros((ids.size, len(conds)))
    np.add.at(s, (inverse, ci), scores["score"].to_numpy())
    np.add.at(n, (inverse, ci), 1.0)
    return ids, s, n


def _boot_rates(s: np.ndarray, n: np.ndarray, n_boot: int, seed: int) -> np.ndarray:
    """(B, k) rates of participant resamples (NaN where a resample has no trial of a condition)."""
    w = bootstrap_weights(s.shape[0], n_boot, seed)
    num, den = w @ s, w @ n
    return np.divide(num, den, out=np.full(num.shape, np.nan), where=den > 0)


def _conds(scores: pd.DataFrame, conditions: Sequence[str] | None) -> list[str]:
    return list(conditions) if conditions is not None else sorted(scores["condition"].unique())


def matched_preference(data: pd.DataFrame, criterion: str | None = None, *, conditions: Sequence[str] | None = None,
                       n_boot: int = 10_000, ci: float = 0.95, seed: int = 0) -> pd.DataFrame:
    """Per condition the matched-preference rate (ties = 0.5) against chance 0.5 (see the module docstring).

    Columns: condition, n (trials), n_participants, matched (matched preferred), equal, mismatched, rate,
    ci_low, ci_high (participant bootstrap, percentile), p (exact binomial test on the trials with a
    preference, two-sided, against 0.5).

    >>> from results_analysis.simulate import simulate_paradigm
    >>> df = simulate_paradigm("mismatch", 24, 6, truth={"A": 0.8, "B": 0.5}, conditions=("A", "B"), seed=2)
    >>> r = matched_preference(df, n_boot=500)
    >>> r[["condition", "n", "rate"]].round(2).values.tolist(), bool(r.p.iloc[0] < .001), bool(r.p.iloc[1] > .05)
    ([['A', 72, 0.75], ['B', 72, 0.46]], True, True)
    """
    scores = data if {"score", "condition"} <= set(data.columns) else trial_scores(data, criterion)
    conds = _conds(scores, conditions)
    ids, s, n = _participant_sums(scores, conds)
    boot = _boot_rates(s, n, n_boot, seed) if n_boot > 0 and ids.size >= 2 else None
    a = (1.0 - ci) / 2.0
    rows = []
    for i, c in enumerate(conds):
        sc = scores.loc[scores["condition"] == c, "score"].to_numpy()
        won, tied, lost = int((sc == 1).sum()), int((sc == 0.5).sum()), int((sc == 0).sum())
        lo = hi = np.nan
        if boot is not None and np.isfinite(boot[:, i]).any():
            lo, hi = np.nanquantile(boot[:, i], [a, 1.0 - a])
        rows.append({"condition": c, "n": int(sc.size), "n_participants": int((n[:, i] > 0).sum()),
                     "matched": won, "equal": tied, "mismatched": lost,
                     "rate": float(sc.mean()) if sc.size else np.nan, "ci_low": lo, "ci_high": hi,
                     "p": float(stats.binomtest(won, won + lost, 0.5).pvalue) if won + lost else np.nan})
    out = pd.DataFrame(rows)
    out.attrs.update(n_boot=n_boot, ci=ci, seed=seed, chance=0.5, ties="half a preference for the matched motion")
    return out


def barnard_table(won: int, tied: int, lost: int, *, ties: str = "split") -> tuple[int, int]:
    """One condition's row of Barnard's 2x2 table: (matched preferred, not), ties split (the odd one to
    "not") or dropped.

    >>> barnard_table(10, 5, 3), barnard_table(10, 5, 3, ties="drop")
    ((12, 6), (10, 3))
    """
    if ties not in BARNARD_TIES:
        raise ValueError(f"ties must be one of {', '.join(BARNARD_TIES)}, not {ties!r}")
    if ties == "drop":
        return won, lost
    return won + tied // 2, lost + tied - tied // 2


def compare_conditions(data: pd.DataFrame, criterion: str | None = None, *, conditions: Sequence[str] | None = None,
                       n_boot: int = 10_000, ci: float = 0.95, seed: int = 0, adjust: str = "holm",
                       ties: str = "split") -> pd.DataFrame:
    """Every pair of conditions compared on their matched-preference rates (see the module docstring).

    Columns: a, b, rate_a, rate_b, difference (a - b), ci_low, ci_high (bootstrap of the difference),
    p_bootstrap, p_bootstrap_adjusted, table (Barnard's [[a matched, a not], [b matched, b not]]), p_barnard,
    p_barnard_adjusted, adjustment.

    >>> from results_analysis.simulate import simulate_paradigm
    >>> df = simulate_paradigm("mismatch", 24, 6, truth={"A": 0.85, "B": 0.5, "C": 0.5}, seed=2)
    >>> c = compare_conditions(df, n_boot=500)
    >>> c[["a", "b"]].values.tolist(), (c.p_barnard_adjusted < 0.05).tolist()
    ([['A', 'B'], ['A', 'C'], ['B', 'C']], [True, True, False])
    """
    scores = data if {"score", "condition"} <= set(data.columns) else trial_scores(data, criterion)
    conds = _conds(scores, conditions)
    rates = matched_preference(scores, conditions=conds, n_boot=0)
    ids, s, n = _participant_sums(scores, conds)
    boot = _boot_rates(s, n, n_boot, seed) if n_boot > 0 and ids.size >= 2 else None
    a = (1.0 - ci) / 2.0
    rows = []
    for i in range(len(conds)):
        for j in range(i + 1, len(conds)):
            ri, rj = rates.iloc[i], rates.iloc[j]
            table = [list(barnard_table(ri.matched, ri.equal, ri.mismatched, ties=ties)),
                     list(barnard_table(rj.matched, rj.equal, rj.mismatched, ties=ties))]
            usable = min(sum(table[0]), sum(table[1])) > 0 and table[0][0] + table[1][0] + table[0][1] + table[1][1] > 0
            p_barnard = float(stats.barnard_exact(table, alternative="two-sided").pvalue) if usable else np.nan
            lo = hi = p_boot = np.nan
            if boot is not None:
                d = boot[:, i] - boot[:, j]
                d = d[np.isfinite(d)]
                if d.size:
                    lo, hi = np.quantile(d, [a, 1.0 - a])
                    p_boot = float(min(1.0, 2.0 * min((d <= 0).mean(), (d >= 0).mean())))
            rows.append({"a": conds[i], "b": conds[j], "rate_a": ri.rate, "rate_b": rj.rate,
                         "difference": ri.rate - rj.rate, "ci_low": lo, "ci_high": hi, "p_bootstrap": p_boot,
                         "table": table, "p_barnard": p_barnard})
    out = pd.DataFrame(rows, columns=["a", "b", "rate_a", "rate_b", "difference", "ci_low", "ci_high",
                                      "p_bootstrap", "table", "p_barnard"])
    for col in ("p_bootstrap", "p_barnard"):
        p = out[col].to_numpy(dtype=float)
        adj = np.full(p.size, np.nan)
        ok = np.isfinite(p)
        adj[ok] = adjust_pvalues(p[ok], adjust)
        out.insert(out.columns.get_loc(col) + 1, f"{col}_adjusted", adj)
    out["adjustment"] = ADJUSTMENT_NAMES[adjust]
    out.attrs.update(n_boot=n_boot, ci=ci, seed=seed, adjust=adjust, ties=ties)
    return out
