"""Pairwise-preference blocks: Bradley-Terry strengths reported as Elo, with participant-bootstrap intervals,
and the win/tie/loss matrix (the GENEA Leaderboard's analysis of its HEMVIP2 answers).

Outcomes. A trial shows conditions ``a`` (left) and ``b`` (right) and records a preference -2..2 for ``a``
(:func:`results_analysis.paradigms.preference_trials`): any positive level is a win of ``a``, any negative one a
win of ``b`` (clearly and slightly count the same), 0 ("equal") a tie. With ``ties='half'`` (the default, as
GENEA does) a tie counts as half a win for each condition; ``ties='drop'`` leaves tied trials out of the fit.

Bradley-Terry. P(i preferred to j) = p_i / (p_i + p_j), fitted by maximum likelihood to the (half-)win
counts with :func:`results_analysis.bradley_terry.fit_bradley_terry` (Newton's method to convergence; the same
estimability rule: a condition that never won or never lost has no finite strength and is reported as not
estimable, never given a made-up number).

Elo. elo_i = 400 log10 p_i, anchored so that the mean Elo of the estimable conditions is 0 (the anchor is
arbitrary: only differences mean anything). A difference d gives P(preferred) = 1 / (1 + 10^(-d/400)): a
difference of 200 = preferred 76 % of the time (:func:`elo_win_probability`).

Intervals. ``n_boot`` (10,000 by default, as GENEA) resamples of participants with replacement (each
participant's win counts kept together), seeded, all fitted at once as one stack of win matrices; each
resample's Elo is anchored to mean 0 like the estimate, and the interval is the percentile interval. The same
resamples give each pair's Elo difference its interval and a bootstrap p-value (:func:`elo_differences`). A
resample in which a condition happens never to win is kept finite by a pseudo-count of
:data:`results_analysis.bradley_terry.BOOT_PRIOR` wins each way per pair.
"""
from __future__ import annotations

import json
from collections.abc import Sequence

import numpy as np
import pandas as pd

from results_analysis.bradley_terry import BOOT_PRIOR, estimability, fit_bradley_terry
from results_analysis.descriptives import bootstrap_weights
from results_analysis.errors import AnalysisInputError
from results_analysis.paradigms import preference_trials

#: How a tie ("equal") enters the Bradley-Terry fit.
TIES = ("half", "drop")
#: Elo points per unit of natural log-strength: elo = 400 log10 p = ELO_PER_LOG * ln p.
ELO_PER_LOG = 400.0 / np.log(10.0)


def elo_win_probability(d: float | np.ndarray) -> np.ndarray:
    """P(a condition is preferred to one ``d`` Elo below it) = 1 / (1 + 10^(-d/400)).

    >>> round(float(elo_win_probability(200)), 4), float(elo_win_probability(0))
    (0.7597, 0.5)
    """
    return 1.0 / (1.0 + 10.0 ** (-np.asarray(d, dtype=float) / 400.0))


def _trials(data: pd.DataFrame, criterion: str | None) -> pd.DataFrame:
    """Trial outcomes (``a``, ``b``, ``pref_a``) of ``data``: tidy rows or :func:`preference_trials` output."""
    if criterion is not None:
        data = data[data["criterion"] == criterion]
    if {"a", "b", "pref_a"} <= set(data.columns):
        return data
    return preference_trials(data)


def _conditions(trials: pd.DataFrame, conditions: Sequence[str] | None) -> list[str]:
    if conditions is not None:
        return list(conditions)
    return sorted(set(trials["a"]) | set(trials["b"]))


def win_matrix(data: pd.DataFrame, criterion: str | None = None, *,
               conditions: Sequence[str] | None = None) -> pd.DataFrame:
    """Wins, ties and losses per ordered pair (a, b): how often ``a`` was preferred to ``b``, judged equal, or
    ``b`` preferred; ``score`` = (wins + ties / 2) / n, the share of points ``a`` took off ``b``.

    ``data``: tidy rows of a pairwise block (or :func:`results_analysis.paradigms.preference_trials`).

    >>> t = pd.DataFrame({"a": ["X", "X", "Y"], "b": ["Y", "Y", "X"], "pref_a": [2, 0, -1]})
    >>> win_matrix(t).values.tolist()
    [['X', 'Y', 2, 1, 0, 3, 0.8333333333333334], ['Y', 'X', 0, 1, 2, 3, 0.16666666666666666]]
    """
    t = _trials(data, criterion)
    conds = _conditions(t, conditions)
    idx = {c: i for i, c in enumerate(conds)}
    k = len(conds)
    wins, ties = np.zeros((k, k), dtype=int), np.zeros((k, k), dtype=int)
    ia, ib = t["a"].map(idx).to_numpy(), t["b"].map(idx).to_numpy()
    pref = np.asarray(t["pref_a"], dtype=float)
    np.add.at(wins, (ia[pref > 0], ib[pref > 0]), 1)
    np.add.at(wins, (ib[pref < 0], ia[pref < 0]), 1)
    np.add.at(ties, (ia[pref == 0], ib[pref == 0]), 1)
    ties = ties + ties.T
    rows = []
    for i in range(k):
        for j in range(k):
            if i == j:
                continue
            n = int(wins[i, j] + ties[i, j] + wins[j, i])
            rows.append({"a": conds[i], "b": conds[j], "wins": int(wins[i, j]), "ties": int(ties[i, j]),
                         "losses": int(wins[j, i]), "n": n,
                         "score": (wins[i, j] + ties[i, j] / 2) / n if n else np.nan})
    return pd.DataFrame(rows, columns=["a", "b", "wins", "ties", "losses", "n", "score"])


def participant_win_matrices(data: pd.DataFrame, criterion: str | None = None, *,
                             conditions: Sequence[str] | None = None,
                             ties: str = "half") -> tuple[np.ndarray, np.ndarray]:
    """Participants (sorted) and their (P, k, k) win counts: [p, i, j] = wins of i over j by participant p,
    a tie half a win each (``ties='half'``) or left out (``ties='drop'``).

    >>> t = pd.DataFrame({"participant": ["P1", "P1", "P2"], "a": ["X", "X", "Y"], "b": ["Y", "Y", "X"],
    ...                   "pref_a": [1, 0, 2]})
    >>> ids, w = participant_win_matrices(t)
    >>> ids.tolist(), w[0].tolist(), w[1].tolist()
    (['P1', 'P2'], [[0.0, 1.5], [0.5, 0.0]], [[0.0, 0.0], [1.0, 0.0]])
    """
    if ties not in TIES:
        raise ValueError(f"ties must be one of {', '.join(TIES)}, not {ties!r}")
    t = _trials(data, criterion)
    conds = _conditions(t, conditions)
    idx = {c: i for i, c in enumerate(conds)}
    missing = (set(t["a"]) | set(t["b"])) - set(idx)
    if missing:
        raise ValueError(f"condition(s) {', '.join(sorted(missing))} not among the conditions given")
    ids, inverse = np.unique(t["participant"].astype(str).to_numpy(), return_inverse=True)
    pref = np.asarray(t["pref_a"], dtype=float)
    score_a = np.where(pref > 0, 1.0, np.where(pref < 0, 0.0, 0.5))
    keep = pref != 0 if ties == "drop" else np.ones(pref.size, dtype=bool)
    ia, ib = t["a"].map(idx).to_numpy(), t["b"].map(idx).to_numpy()
    w = np.zeros((ids.size, len(conds), len(conds)))
    np.add.at(w, (inverse[keep], ia[keep], ib[keep]), score_a[keep])
    np.add.at(w, (inverse[keep], ib[keep], ia[keep]), 1.0 - score_a[keep])
    return ids, w


def _elo(strengths: np.ndarray) -> np.ndarray:
    """Elo of strengths (..., k), anchored to mean 0 along the last axis."""
    e = ELO_PER_LOG * np.log(strengths)
    return e - e.mean(axis=-1, keepdims=True)


def _boot_elo(per: np.ndarray, n_boot: int, seed: int) -> np.ndarray:
    """(n_boot, k) Elo (mean 0) of participant resamples of the (P, k, k) win counts, fitted as one stack."""
    weights = bootstrap_weights(per.shape[0], n_boot, seed)
    return _elo(fit_bradley_terry(np.einsum("bp,pij->bij", weights, per), prior=BOOT_PRIOR, tol=1e-8))


def bradley_terry_elo(data: pd.DataFrame, criterion: str | None = None, *, conditions: Sequence[str] | None = None,
                      ties: str = "half", n_boot: int = 10_000, ci: float = 0.95, seed: int = 0) -> pd.DataFrame:
    """Bradley-Terry strengths of a pairwise block as Elo, with participant-bootstrap percentile intervals.

    ``data``: the block's tidy rows (or :func:`results_analysis.paradigms.preference_trials`), of one
    ``criterion`` when given. Columns: condition, elo (mean 0), ci_low, ci_high (of the Elo), strength (sums to
    1), score (share of its comparisons' points: wins + ties/2), n (comparisons), estimable, note. The
    ``attrs`` record n_boot, ci, seed, ties and the anchor.

    >>> from results_analysis.simulate import simulate_paradigm
    >>> df = simulate_paradigm("pairwise", 30, 6, truth={"A": 200, "B": 0, "C": -200}, tie_rate=0.1, seed=4)
    >>> bt = bradley_terry_elo(df, n_boot=300)
    >>> bt["elo"].round(-1).tolist(), bool((bt.ci_low < bt.elo).all() and (bt.elo < bt.ci_high).all())
    ([180.0, 0.0, -180.0], True)
    """
    ids, per = participant_win_matrices(data, criterion, conditions=conditions, ties=ties)
    t = _trials(data, criterion)
    conds = _conditions(t, conditions)
    k = len(conds)
    if k < 2 or ids.size == 0:
        raise AnalysisInputError(data.attrs.get("source"), f"criterion {criterion}" if criterion else None,
                                 "a pairwise analysis needs answers comparing at least 2 conditions")
    wins = per.sum(axis=0)
    estimable, notes = estimability(wins, conds)
    keep = np.flatnonzero(estimable)
    p, elo = np.full(k, np.nan), np.full(k, np.nan)
    lo, hi = np.full(k, np.nan), np.full(k, np.nan)
    if keep.size:
        p[keep] = fit_bradley_terry(wins[np.ix_(keep, keep)])
        elo[keep] = _elo(p[keep])
        if n_boot > 0 and ids.size >= 2:
            e = _boot_elo(per[:, keep][:, :, keep], n_boot, seed)
            a = (1.0 - ci) / 2.0
            lo[keep], hi[keep] = np.quantile(e, a, axis=0), np.quantile(e, 1.0 - a, axis=0)
    games = wins + wins.T
    n = games.sum(axis=1)
    out = pd.DataFrame({"condition": conds, "elo": elo, "ci_low": lo, "ci_high": hi, "strength": p,
                        "score": np.divide(wins.sum(axis=1), n, out=np.full(k, np.nan), where=n > 0),
                        "n": n, "estimable": estimable, "note": notes})
    out.attrs.update(n_boot=n_boot, ci=ci, seed=seed, ties=ties, anchor="mean Elo of the estimable conditions = 0",
                     n_participants=int(ids.size))
    return out


def elo_differences(data: pd.DataFrame, criterion: str | None = None, *, conditions: Sequence[str] | None = None,
                    ties: str = "half", n_boot: int = 10_000, ci: float = 0.95, seed: int = 0,
                    adjust: str = "holm") -> pd.DataFrame:
    """Every pair of estimable conditions: the Elo difference a - b, the probability it implies that ``a`` is
    preferred (:func:`elo_win_probability`), a percentile interval of the difference from the same participant
    resamples as :func:`bradley_terry_elo` (same ``seed``), and a two-sided bootstrap p-value (twice the smaller
    share of resampled differences on either side of 0, each counted as (1 + count) / (1 + B)), adjusted over the
    pairs (``adjust``: :data:`results_analysis.adjust.ADJUSTMENTS`).

    Columns: a, b, difference, p_preferred, ci_low, ci_high, p, p_adjusted, adjustment.

    >>> from results_analysis.simulate import simulate_paradigm
    >>> df = simulate_paradigm("pairwise", 30, 6, truth={"A": 200, "B": 0, "C": -200}, tie_rate=0.1, seed=4)
    >>> d = elo_differences(df, n_boot=300)
    >>> d[["a", "b"]].values.tolist(), (d.p_adjusted < 0.05).tolist()
    ([['A', 'B'], ['A', 'C'], ['B', 'C']], [True, True, True])
    """
    from results_analysis.adjust import ADJUSTMENT_NAMES, adjust_pvalues

    ids, per = participant_win_matrices(data, criterion, conditions=conditions, ties=ties)
    elo = bradley_terry_elo(data, criterion, conditions=conditions, ties=ties, n_boot=0)
    keep = np.flatnonzero(elo["estimable"].to_numpy())
    names = elo["condition"].tolist()
    boot = _boot_elo(per[:, keep][:, :, keep], n_boot, seed) if n_boot > 0 and ids.size >= 2 and keep.size else None
    a = (1.0 - ci) / 2.0
    rows = []
    for x in range(keep.size):
        for y in range(x + 1, keep.size):
            i, j = keep[x], keep[y]
            d = float(elo["elo"].iloc[i] - elo["elo"].iloc[j])
            lo = hi = p = np.nan
            if boot is not None:
                bd = boot[:, x] - boot[:, y]
                lo, hi = np.quantile(bd, [a, 1.0 - a])
                p = float(min(1.0, 2.0 * (1 + min((bd <= 0).sum(), (bd >= 0).sum())) / (1 + bd.size)))
            rows.append({"a": names[i], "b": names[j], "difference": d, "p_preferred": float(elo_win_probability(d)),
                         "ci_low": lo, "ci_high": hi, "p": p})
    out = pd.DataFrame(rows, columns=["a", "b", "difference", "p_preferred", "ci_low", "ci_high", "p"])
    adj = np.full(len(out), np.nan)
    ok = np.isfinite(out["p"].to_numpy(dtype=float))
    adj[ok] = adjust_pvalues(out["p"].to_numpy(dtype=float)[ok], adjust)
    out["p_adjusted"] = adj
    out["adjustment"] = ADJUSTMENT_NAMES[adjust]
    out.attrs.update(n_boot=n_boot, ci=ci, seed=seed, ties=ties, adjust=adjust)
    return out


def reason_counts(data: pd.DataFrame, criterion: str | None = None, *,
                  conditions: Sequence[str] | None = None) -> pd.DataFrame:
    """How often each reason was given, per preferred condition: one row per reason, columns n (trials it was
    given in), share (of the trials with a preference, where reasons are asked) and one count per condition
    (``preferred_<condition>``: trials in which that condition was preferred and the reason given). Reasons are
    the JSON lists of the ``reasons`` column; a cell that is not a JSON list of texts is an error naming its row.

    >>> t = pd.DataFrame({"a": ["X", "X", "Y"], "b": ["Y", "Y", "X"], "pref_a": [2, -1, 0],
    ...                   "reasons": ['["Hands"]', '["Hands", "Timing"]', "[]"]})
    >>> reason_counts(t).values.tolist()
    [['Hands', 2, 1.0, 1, 1], ['Timing', 1, 0.5, 0, 1]]
    """
    from results_analysis.errors import AnalysisInputError

    t = _trials(data, criterion)
    conds = _conditions(t, conditions)
    decided = t[np.asarray(t["pref_a"], dtype=float) != 0]
    counts: dict[str, dict[str, int]] = {}
    where = decided["_where"] if "_where" in decided.columns else [f"trial {i + 1}" for i in range(len(decided))]
    for w, text, pref, a, b in zip(where, decided["reasons"] if "reasons" in decided.columns
                                   else [None] * len(decided), decided["pref_a"], decided["a"], decided["b"]):
        if text is None or (isinstance(text, float) and np.isnan(text)) or str(text).strip() == "":
            continue
        try:
            reasons = json.loads(str(text))
        except json.JSONDecodeError:
            reasons = None
        if not isinstance(reasons, list) or not all(isinstance(r, str) for r in reasons):
            raise AnalysisInputError(data.attrs.get("source"), f"{w}, column 'reasons'",
                                     f"{text!r} is not a JSON list of reasons")
        winner = a if float(pref) > 0 else b
        for r in dict.fromkeys(reasons):
            counts.setdefault(r, {c: 0 for c in conds})[winner] += 1
    rows = [{"reason": r, "n": sum(by.values()), "share": sum(by.values()) / len(decided) if len(decided) else np.nan,
             **{f"preferred_{c}": by[c] for c in conds}} for r, by in counts.items()]
    out = pd.DataFrame(rows, columns=["reason", "n", "share", *[f"preferred_{c}" for c in conds]])
    return out.sort_values(["n", "reason"], ascending=[False, True], kind="stable").reset_index(drop=True)
