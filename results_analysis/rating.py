"""Rating blocks (MUSHRA-style 0-100 sliders, HEMVIP v1): means with intervals, Friedman and Wilcoxon-Holm.

Each trial shows k figures side by side and the participant rates each on a 0..100 slider per criterion.

* :func:`participant_means` — the blocks of the tests: each participant's mean rating per condition (a
  participant's trials are repeated measures of one person, so the participant is the unit, as in the rank
  analysis).
* :func:`rating_summary` — per condition the mean of all its ratings with a percentile participant-bootstrap
  interval (participants resampled whole, seeded; a resample's mean is its rating total over its rating
  count), the median and the standard deviation.
* :func:`rating_tests` — the Friedman test (:func:`results_analysis.friedman.friedman`: average ranks within
  each participant, tie-corrected) on the participant means and pairwise Wilcoxon signed-rank tests on the same
  paired means with Holm adjustment (:func:`results_analysis.posthoc.wilcoxon_holm`, R's ``wilcox.test``
  conventions). The hidden reference is left out of both by default: it is there to check the raters, and a
  test that it beats the systems says nothing about them.
* :func:`screen_reference` — MUSHRA's post-screening (ITU-R BS.1534-3, 4.1.2): a participant who rates the
  hidden reference below ``threshold`` (90) in more than ``max_share`` (15 %) of the items (an item is one trial
  and criterion) did not hear, here see, the difference and is excluded from the block's analysis; the table
  says who and why. Participants who rated no reference are never excluded by it.
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

from results_analysis.adjust import ADJUSTMENTS
from results_analysis.descriptives import bootstrap_weights
from results_analysis.errors import AnalysisInputError
from results_analysis.friedman import friedman
from results_analysis.paradigms import check_rating_rows
from results_analysis.posthoc import wilcoxon_holm

#: MUSHRA's post-screening rule: the reference rated below THRESHOLD in more than MAX_SHARE of the items.
SCREEN_THRESHOLD = 90.0
SCREEN_MAX_SHARE = 0.15


def _rows(data: pd.DataFrame, criterion: str | None) -> pd.DataFrame:
    if criterion is not None:
        data = data[data["criterion"] == criterion]
    out = data.assign(rating=check_rating_rows(data).to_numpy())
    out.attrs.update(data.attrs)
    return out


def _conds(rows: pd.DataFrame, conditions: Sequence[str] | None) -> list[str]:
    return list(conditions) if conditions is not None else sorted(rows["condition"].astype(str).unique())


def participant_means(data: pd.DataFrame, criterion: str | None = None, *,
                      conditions: Sequence[str] | None = None) -> pd.DataFrame:
    """Wide frame: one row per participant, one column per condition, the participant's mean rating.

    >>> t = pd.DataFrame({"participant": ["P1"] * 4, "trial_index": [0, 0, 1, 1], "criterion": "c",
    ...                   "condition": ["A", "B", "A", "B"], "rating": [80, 40, 60, 50]})
    >>> participant_means(t).values.tolist()
    [[70.0, 45.0]]
    """
    rows = _rows(data, criterion)
    conds = _conds(rows, conditions)
    wide = rows.pivot_table(index="participant", columns="condition", values="rating", aggfunc="mean",
                            observed=True)
    return wide.reindex(columns=conds).rename_axis(columns=None)


def rating_summary(data: pd.DataFrame, criterion: str | None = None, *, conditions: Sequence[str] | None = None,
                   n_boot: int = 2000, ci: float = 0.95, seed: int = 0) -> pd.DataFrame:
    """Per condition: n (ratings), n_participants, mean, ci_low, ci_high (participant bootstrap), median, sd.

    >>> from results_analysis.simulate import simulate_paradigm
    >>> df = simulate_paradigm("rating", 20, 4, truth={"A": 70, "B": 40}, conditions=("A", "B"), seed=3)
    >>> s = rating_summary(df, n_boot=400)
    >>> s["mean"].round().tolist(), bool((s.ci_low < s["mean"]).all() and (s["mean"] < s.ci_high).all())
    ([70.0, 42.0], True)
    """
    rows = _rows(data, criterion)
    conds = _conds(rows, conditions)
    ids, inverse = np.unique(rows["participant"].astype(str).to_numpy(), return_inverse=True)
    idx = {c: i for i, c in enumerate(conds)}
    ci_col = rows["condition"].astype(str).map(idx).to_numpy()
    known = ~pd.isna(ci_col)
    ci_col = ci_col[known].astype(int)
    values = rows["rating"].to_numpy()[known]
    s = np.zeros((ids.size, len(conds)))
    n = np.zeros((ids.size, len(conds)))
    np.add.at(s, (inverse[known], ci_col), values)
    np.add.at(n, (inverse[known], ci_col), 1.0)
    lo, hi = np.full(len(conds), np.nan), np.full(len(conds), np.nan)
    if n_boot > 0 and ids.size >= 2:
        w = bootstrap_weights(ids.size, n_boot, seed)
        num, den = w @ s, w @ n
        boot = np.divide(num, den, out=np.full(num.shape, np.nan), where=den > 0)
        a = (1.0 - ci) / 2.0
        for i in range(len(conds)):
            if np.isfinite(boot[:, i]).any():
                lo[i], hi[i] = np.nanquantile(boot[:, i], [a, 1.0 - a])
    rows_out = []
    for i, c in enumerate(conds):
        v = values[ci_col == i]
        rows_out.append({"condition": c, "n": int(v.size), "n_participants": int((n[:, i] > 0).sum()),
                         "mean": float(v.mean()) if v.size else np.nan, "ci_low": lo[i], "ci_high": hi[i],
                         "median": float(np.median(v)) if v.size else np.nan,
                         "sd": float(v.std(ddof=1)) if v.size > 1 else np.nan})
    out = pd.DataFrame(rows_out)
    out.attrs.update(n_boot=n_boot, ci=ci, seed=seed)
    return out


def rating_tests(data: pd.DataFrame, criterion: str | None = None, *, conditions: Sequence[str] | None = None,
                 reference: str | None = None, include_reference: bool = False,
                 adjust: str = "holm") -> tuple[pd.DataFrame, pd.DataFrame]:
    """The Friedman table and the Wilcoxon post-hoc table on the participants' mean ratings.

    Participants who did not rate every tested condition are left out of both (a complete block design);
    ``attrs['n_incomplete']`` of the Friedman table counts them. The reference is tested only with
    ``include_reference``. Wilcoxon statistics are on the means as rated (not ranked): V sums the ranks of
    positive differences a - b, r_rb > 0 when ``a`` was rated higher.

    >>> from results_analysis.simulate import simulate_paradigm
    >>> df = simulate_paradigm("rating", 20, 4, truth={"A": 70, "B": 40, "C": 38}, seed=3)
    >>> fr, post = rating_tests(df)
    >>> bool(fr.p.iloc[0] < .001), (post.p_adjusted < .05).tolist()
    (True, [True, True, False])
    """
    if adjust not in ADJUSTMENTS:
        raise ValueError(f"unknown p-value adjustment {adjust!r}: one of {', '.join(ADJUSTMENTS)}")
    wide = participant_means(data, criterion, conditions=conditions)
    if reference is not None and not include_reference and reference in wide.columns:
        wide = wide.drop(columns=[reference])
    complete = wide.dropna(axis=0, how="any")
    if complete.shape[1] < 2 or len(complete) < 2:
        raise AnalysisInputError(data.attrs.get("source"), f"criterion {criterion}" if criterion else None,
                                 f"a rating analysis needs at least 2 participants who rated at least 2 conditions "
                                 f"(have {len(complete)} x {complete.shape[1]})")
    fr = friedman(complete)
    fr.attrs["n_incomplete"] = int(len(wide) - len(complete))
    post = wilcoxon_holm(complete.to_numpy(dtype=float), list(map(str, complete.columns)), adjust=adjust)
    return fr, post


def screen_reference(data: pd.DataFrame, reference: str, *, threshold: float = SCREEN_THRESHOLD,
                     max_share: float = SCREEN_MAX_SHARE) -> pd.DataFrame:
    """Per participant who rated the reference: items (trial x criterion), how many rated it below
    ``threshold``, that share, and ``excluded`` (share > ``max_share``) with the ``reason`` in words.

    >>> t = pd.DataFrame({"participant": ["P1", "P1", "P2", "P2"], "trial_index": [0, 1, 0, 1], "criterion": "c",
    ...                   "condition": "ref", "rating": [95, 40, 100, 92]})
    >>> screen_reference(t, "ref")[["participant", "below", "excluded"]].values.tolist()
    [['P1', 1, True], ['P2', 0, False]]
    """
    rows = _rows(data, None)
    ref = rows[rows["condition"].astype(str) == str(reference)]
    g = ref.groupby("participant", sort=True)["rating"]
    out = pd.DataFrame({"items": g.size(), "below": g.apply(lambda v: int((v < threshold).sum()))})
    out = out.reset_index().astype({"participant": str})
    out["share"] = out["below"] / out["items"]
    out["excluded"] = out["share"] > max_share
    out["reason"] = [f"rated the hidden reference below {threshold:g} in {b} of {n} items "
                     f"({s:.0%} > {max_share:.0%})" if e else ""
                     for b, n, s, e in zip(out["below"], out["items"], out["share"], out["excluded"])]
    out.attrs.update(reference=reference, threshold=threshold, max_share=max_share)
    return out[["participant", "items", "below", "share", "excluded", "reason"]]
