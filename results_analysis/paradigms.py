"""The rows of each response paradigm in a tidy results table, checked and shaped for its analysis.

A study is a sequence of blocks; each block has one paradigm (``rank``, ``pairwise``, ``mismatch`` or
``rating``) and its answers are rows of the one tidy table (one row per participant x trial x criterion x slot;
columns ``block``, ``paradigm``, ``rating``, ``preference``, ``matched``, ``motion_stimulus``, ``reasons``). A
table without a ``paradigm`` column is a rank study: every row is a ``rank`` row of block ``main``.

* :func:`rank_rows` — the rows the rank analyses use (paradigm ``rank``); :func:`blocks` — the other blocks,
  in the order the study ran them.
* :func:`preference_trials` — pairwise and mismatch answers as one row per trial and criterion: the two
  slots' conditions (``a`` left, ``b`` right), the preference for ``a`` (-2..2: +2 = clearly ``a``) and, for
  mismatch, which slot played its own speech's motion. The table's two rows of a trial must be ``p`` and
  ``-p`` (the storage contract); anything else is an error naming the row.
* :func:`check_rating_rows` — ratings present and within 0..100.

Practice and attention-check rows are never part of a paradigm analysis (they belong to the first rank block).
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from results_analysis.errors import AnalysisInputError

#: The paradigms a block can have.
PARADIGMS = ("rank", "pairwise", "mismatch", "rating")
#: Paradigms answered with a preference between two slots.
PREFERENCE_PARADIGMS = ("pairwise", "mismatch")


def paradigm_of(df: pd.DataFrame) -> pd.Series:
    """Each row's paradigm ("rank" for a table without the column, or where it is empty).

    >>> paradigm_of(pd.DataFrame({"paradigm": ["rating", None, ""]})).tolist()
    ['rating', 'rank', 'rank']
    """
    if "paradigm" not in df.columns:
        return pd.Series("rank", index=df.index, dtype=object)
    return df["paradigm"].fillna("rank").replace("", "rank")


def rank_rows(df: pd.DataFrame) -> pd.DataFrame:
    """The rows the rank analyses use: paradigm ``rank`` (all rows of a table without paradigms).

    >>> t = pd.DataFrame({"paradigm": ["rank", "pairwise", None], "rank": [1.0, None, 2.0]})
    >>> rank_rows(t)["rank"].tolist()
    [1.0, 2.0]
    """
    if "paradigm" not in df.columns:
        return df
    mine = _is_rank(df)
    out = df.copy(deep=False) if mine.all() else df[mine]  # a study of rank blocks only: no copy of every column
    out.attrs.update(df.attrs)
    return out


def other_rows(df: pd.DataFrame) -> pd.DataFrame:
    """The rows of the pairwise, mismatch and rating blocks (none in a table without paradigms).

    >>> other_rows(pd.DataFrame({"paradigm": ["rank", "pairwise"], "rank": [1.0, None]}))["paradigm"].tolist()
    ['pairwise']
    """
    out = df.iloc[:0] if "paradigm" not in df.columns else df[~_is_rank(df)]
    out.attrs.update(df.attrs)
    return out


def _is_rank(df: pd.DataFrame) -> np.ndarray:
    """``(paradigm_of(df) == "rank").to_numpy()`` for a frame with the column, by one comparison of the column
    with "rank"; only the (few) other cells are looked at again for an empty or missing paradigm."""
    try:
        out = np.asarray(df["paradigm"].to_numpy(dtype=object) == "rank", dtype=bool)
    except TypeError:  # a value that does not compare to a bool (pd.NA): the general rule for every row
        return (paradigm_of(df) == "rank").to_numpy()
    other = np.flatnonzero(~out)
    if other.size:
        out[other] = (paradigm_of(df.iloc[other]) == "rank").to_numpy()
    return out


def blocks(df: pd.DataFrame) -> list[tuple[str, str]]:
    """(block, paradigm) of every non-rank block, in the order the study ran them (first trial index); an
    unknown paradigm is an error naming its row.

    >>> t = pd.DataFrame({"block": ["m", "p", "p"], "paradigm": ["mismatch", "pairwise", "pairwise"],
    ...                   "trial_index": [5, 1, 2]})
    >>> blocks(t)
    [('p', 'pairwise'), ('m', 'mismatch')]
    """
    if "paradigm" not in df.columns or df.empty:
        return []
    par = paradigm_of(df)
    bad = ~par.isin(PARADIGMS)
    if bad.any():
        i = int(np.argmax(bad.to_numpy()))
        raise AnalysisInputError(df.attrs.get("source"), f"{_where(df, i)}, column 'paradigm'",
                                 f"{par.iloc[i]!r} is not one of {', '.join(PARADIGMS)}")
    sub = df.loc[par != "rank"].assign(_par=par[par != "rank"])
    if sub.empty:
        return []
    first = sub.groupby(["block", "_par"], sort=False)["trial_index"].min().sort_values(kind="stable")
    return [(str(b), str(p)) for b, p in first.index]


def analysed_rows(df: pd.DataFrame, block: str) -> pd.DataFrame:
    """The rows of ``block`` that are analysed: neither practice nor attention check.

    >>> t = pd.DataFrame({"block": ["b", "b", "c"], "is_practice": [True, False, False]})
    >>> analysed_rows(t, "b").index.tolist()
    [1]
    """
    mask = (df["block"] == block).to_numpy(copy=True) if "block" in df.columns else np.ones(len(df), dtype=bool)
    for col in ("is_practice", "is_attention_check"):
        if col in df.columns:
            mask &= ~df[col].astype(bool).to_numpy()
    out = df[mask]
    out.attrs.update(df.attrs)
    return out


def _where(df: pd.DataFrame, i: int) -> str:
    return str(df["_where"].iloc[i]) if "_where" in df.columns else f"row {i + 1}"


def preference_trials(df: pd.DataFrame) -> pd.DataFrame:
    """One row per trial x criterion of pairwise/mismatch rows: participant, trial_index, stimulus, criterion,
    a, b (the conditions of the first and second slot), pref_a (preference for ``a``, -2..2), a_matched
    (mismatch: 1.0 when slot ``a`` played its own speech's motion, 0.0 when slot ``b`` did; NaN for pairwise)
    and reasons.

    >>> t = pd.DataFrame({"participant": "P1", "trial_index": 0, "stimulus": "s", "criterion": "c",
    ...                   "condition": ["A", "B"], "slot": [0, 1], "preference": [-1.0, 1.0]})
    >>> preference_trials(t)[["a", "b", "pref_a"]].values.tolist()
    [['A', 'B', -1.0]]
    """
    src = df.attrs.get("source")
    if "preference" not in df.columns:
        raise AnalysisInputError(src, "column 'preference'", "missing: pairwise and mismatch rows need it")
    pref = pd.to_numeric(df["preference"], errors="coerce")
    bad = pref.isna() | (pref.abs() > 2) | (pref != pref.round())
    if bad.any():
        i = int(np.argmax(bad.to_numpy()))
        raise AnalysisInputError(src, f"{_where(df, i)}, column 'preference'",
                                 f"{df['preference'].iloc[i]!r} is not a preference -2..2")
    key = ["participant", "trial_index", "criterion"]
    order = df.assign(_slot=df["slot"] if "slot" in df.columns else np.arange(len(df)), _row=np.arange(len(df)))
    order = order.sort_values(key + ["_slot"], kind="stable")
    size = order.groupby(key, sort=False)["condition"].transform("size")
    if (size != 2).any():
        i = int(order["_row"].to_numpy()[np.argmax((size != 2).to_numpy())])
        raise AnalysisInputError(src, f"{_where(df, i)} (participant {df['participant'].iloc[i]}, trial "
                                 f"{df['trial_index'].iloc[i]:g}, criterion {df['criterion'].iloc[i]})",
                                 f"a two-slot trial has {int(size.iloc[np.argmax((size != 2).to_numpy())])} "
                                 "row(s) for this criterion, not 2")
    first, second = order.iloc[0::2], order.iloc[1::2]
    pa, pb = pref.to_numpy()[first["_row"].to_numpy()], pref.to_numpy()[second["_row"].to_numpy()]
    off = pa != -pb
    if off.any():
        i = int(second["_row"].to_numpy()[np.argmax(off)])
        raise AnalysisInputError(src, f"{_where(df, i)}, column 'preference'",
                                 f"the two slots of a trial must hold p and -p, not {pa[np.argmax(off)]:g} and "
                                 f"{pb[np.argmax(off)]:g}")
    out = pd.DataFrame({"participant": first["participant"].to_numpy(),
                        "trial_index": first["trial_index"].to_numpy(),
                        "stimulus": first["stimulus"].to_numpy(), "criterion": first["criterion"].to_numpy(),
                        "a": first["condition"].to_numpy(), "b": second["condition"].to_numpy(), "pref_a": pa})
    if "matched" in df.columns:
        m = pd.to_numeric(df["matched"], errors="coerce").to_numpy()
        ma, mb = m[first["_row"].to_numpy()], m[second["_row"].to_numpy()]
        out["a_matched"] = ma
        mismatch = (paradigm_of(df).to_numpy()[first["_row"].to_numpy()] == "mismatch")
        wrong = mismatch & ~(((ma == 1) & (mb == 0)) | ((ma == 0) & (mb == 1)))
        if wrong.any():
            i = int(first["_row"].to_numpy()[np.argmax(wrong)])
            raise AnalysisInputError(src, f"{_where(df, i)}, column 'matched'",
                                     "a mismatch trial needs one slot with matched = 1 and the other with 0")
        same = mismatch & (out["a"].to_numpy() != out["b"].to_numpy())
        if same.any():
            i = int(first["_row"].to_numpy()[np.argmax(same)])
            raise AnalysisInputError(src, f"{_where(df, i)}, column 'condition'",
                                     "both slots of a mismatch trial show the same condition")
    else:
        out["a_matched"] = np.nan
    out["reasons"] = first["reasons"].to_numpy() if "reasons" in df.columns else None
    out["_where"] = [_where(df, int(i)) for i in first["_row"].to_numpy()]
    return out


def check_rating_rows(df: pd.DataFrame) -> pd.Series:
    """The ``rating`` column as numbers, each checked to be within 0..100, and no condition rated twice on one
    criterion of a trial (an error names the first bad row).

    >>> check_rating_rows(pd.DataFrame({"rating": ["12.5", 100]})).tolist()
    [12.5, 100.0]
    """
    src = df.attrs.get("source")
    if "rating" not in df.columns:
        raise AnalysisInputError(src, "column 'rating'", "missing: rating rows need it")
    r = pd.to_numeric(df["rating"], errors="coerce")
    bad = r.isna() | (r < 0) | (r > 100)
    if bad.any():
        i = int(np.argmax(bad.to_numpy()))
        raise AnalysisInputError(src, f"{_where(df, i)}, column 'rating'",
                                 f"{df['rating'].iloc[i]!r} is not a rating within 0..100")
    key = ["participant", "trial_index", "criterion", "condition"]
    dup = df.duplicated(key, keep="first") if set(key) <= set(df.columns) else pd.Series(False, index=df.index)
    if dup.any():
        i = int(np.argmax(dup.to_numpy()))
        raise AnalysisInputError(src, _where(df, i), f"duplicated rating: participant {df['participant'].iloc[i]}, "
                                 f"trial {df['trial_index'].iloc[i]:g}, criterion {df['criterion'].iloc[i]}, "
                                 f"condition {df['condition'].iloc[i]} appears more than once")
    return r.astype(float)
