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
  side of 0, each share counted as (1 + count) / (1 + B) so that B resamples never claim p = 0), and Barnard's
  exact test (:func:`barnard_exact`: scipy.stats.barnard_exact's definition, two-sided,
  pooled Wald statistic, with tied tables counted as extreme) on the
  2x2 table whose columns are the two conditions (the samples, whose totals Barnard's test holds fixed) and
  whose rows are "matched preferred" and "not": [[a matched, b matched], [a not, b not]]. Ties enter that table split: half of a
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
#: Relative tolerance within which a table's Wald statistic counts as equal to the observed one.
_TIE_RTOL = 1e-9


def barnard_exact(table: Sequence[Sequence[int]], *, grid: int = 201) -> float:
    """Two-sided p-value of Barnard's unconditional exact test of a 2x2 table whose columns are the samples.

    The definition of ``scipy.stats.barnard_exact(table, alternative="two-sided", pooled=True)``: the pooled
    Wald statistic T = (p1 - p2) / sqrt(p (1 - p) (1/n1 + 1/n2)) of every table with the observed column totals,
    and the p-value sup over the nuisance proportion pi of P(|T| >= |T_obs|). Two differences: a table whose
    statistic equals the observed one (the mirror table, whose statistic is the same number computed in another
    order) is always counted as at least as extreme (relative tolerance 1e-9); scipy 1.17 compares the floats
    exactly and can drop it (for [[7, 8], [12, 3]] it gives 0.0598 instead of 0.0675). And the supremum is
    found on a grid of ``grid`` points over [0, 1], each local maximum refined by bounded Brent's method
    (scipy uses shgo); a column with no trials gives 1.0, as in scipy.

    >>> round(barnard_exact([[7, 12], [8, 3]]), 4), barnard_exact([[0, 5], [0, 4]])
    (0.0682, 1.0)
    """
    from scipy.optimize import minimize_scalar

    t = np.asarray(table, dtype=np.int64)
    if t.shape != (2, 2) or (t < 0).any():
        raise ValueError("table must be a 2x2 table of non-negative counts")
    n1, n2 = (int(v) for v in t.sum(axis=0))
    if n1 == 0 or n2 == 0:
        return 1.0
    x1, x2 = np.arange(n1 + 1)[:, None], np.arange(n2 + 1)[None, :]
    p1, p2 = x1 / n1, x2 / n2
    p = (x1 + x2) / (n1 + n2)
    with np.errstate(divide="ignore", invalid="ignore"):
        wald = np.where(x1 * n2 == x2 * n1, 0.0, (p1 - p2) / np.sqrt(p * (1 - p) * (1 / n1 + 1 / n2)))
    obs = abs(wald[t[0, 0], t[0, 1]])
    extreme = (np.abs(wald) >= obs * (1 - _TIE_RTOL)).astype(float)

    def tail(pis: np.ndarray) -> np.ndarray:
        pis = np.atleast_1d(pis)
        b1 = stats.binom.pmf(np.arange(n1 + 1)[None, :], n1, pis[:, None])
        b2 = stats.binom.pmf(np.arange(n2 + 1)[None, :], n2, pis[:, None])
        return ((b1 @ extreme) * b2).sum(axis=1)

    pis = np.linspace(0.0, 1.0, grid)
    values = tail(pis)
    best = float(values.max())
    peaks = [i for i in range(grid) if values[i] >= values[max(i - 1, 0)] and values[i] >= values[min(i + 1, grid - 1)]]
    for i in sorted(peaks, key=lambda i: -values[i])[:4]:
        lo, hi = pis[max(i - 1, 0)], pis[min(i + 1, grid - 1)]
        res = minimize_scalar(lambda x: -float(tail(np.array([x]))[0]), bounds=(lo, hi), method="bounded",
                              options={"xatol": 1e-10})
        best = max(best, -float(res.fun))
    return float(min(1.0, best))



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
    p_bootstrap, p_bootstrap_adjusted, table (Barnard's [[a matched, b matched], [a not, b not]]), p_barnard,
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
            (ma, na), (mb, nb) = (barnard_table(ri.matched, ri.equal, ri.mismatched, ties=ties),
                                  barnard_table(rj.matched, rj.equal, rj.mismatched, ties=ties))
            # scipy's orientation: one column per sample (its total is fixed), rows matched preferred / not
            table = [[ma, mb], [na, nb]]
            usable = ma + na > 0 and mb + nb > 0
            p_barnard = barnard_exact(table) if usable else np.nan
            lo = hi = p_boot = np.nan
            if boot is not None:
                d = boot[:, i] - boot[:, j]
                d = d[np.isfinite(d)]
                if d.size:
                    lo, hi = np.quantile(d, [a, 1.0 - a])
                    # (1 + count) / (1 + B): a p-value a finite resampling can support, never 0
                    tail_ = min((d <= 0).sum(), (d >= 0).sum())
                    p_boot = float(min(1.0, 2.0 * (1 + tail_) / (1 + d.size)))
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
