"""Checks of a tidy results frame before any statistic is computed.

Errors name the file, the row(s) and the column; a frame mixing study designs only warns, naming the
design hashes, because merging the runs of one study that changed its design slightly can be intended.
"""
from __future__ import annotations

import warnings

import numpy as np
import pandas as pd

from results_analysis.codes import FrameCodes, frame_codes
from results_analysis.errors import AnalysisInputError
from results_analysis.loader import REQUIRED_COLUMNS


#: What to do with a rated trial that does not rank every condition.
INCOMPLETE_MODES = ("error", "drop", "skillings-mack")


class MixedDesignWarning(UserWarning):
    """The results come from more than one study design (different design hashes)."""


def trial_key(df: pd.DataFrame) -> list[str]:
    """Columns that identify one trial: participant and trial_index (the results database's key; a resumed
    session continues the participant's trial numbering, so the session is not needed)."""
    return ["participant", "trial_index"]


def rated_mask(df: pd.DataFrame) -> pd.Series:
    """Rows of rated trials: neither practice nor attention check (those may show other conditions)."""
    mask = pd.Series(True, index=df.index)
    for col in ("is_practice", "is_attention_check"):
        if col in df.columns:
            mask &= ~df[col].astype(bool)
    return mask


def design_hashes(df: pd.DataFrame) -> list:
    """The distinct design hashes of a frame, sorted (missing ones left out): ``sorted(df["design_hash"].dropna()
    .unique())``, by one pass over the column (a dropna of a million-cell text column is a pass of its own).

    >>> design_hashes(pd.DataFrame({"design_hash": ["b", None, "a", "b"]}))
    ['a', 'b']
    """
    if "design_hash" not in df.columns:
        return []
    return sorted(h for h in pd.unique(df["design_hash"].to_numpy(dtype=object)) if not pd.isna(h))


def validate_results(df: pd.DataFrame, *, incomplete: str = "error") -> pd.DataFrame:
    """Check a tidy results frame; return it, without incomplete rated trials when ``incomplete='drop'``.

    Raises :class:`AnalysisInputError` for missing columns, duplicated rows (the same trial, criterion
    and condition twice), ranks outside 1..k and, unless ``incomplete='drop'`` (listwise deletion), for a
    rated trial that does not rank every condition on a criterion. Warns with :class:`MixedDesignWarning`
    when the design hashes differ. Practice and attention-check trials are checked for duplicates and
    ranks within their own trial only: they may show other conditions (e.g. a frozen avatar).

    >>> import pandas as pd
    >>> df = pd.DataFrame({"participant": "P1", "trial_index": 0, "stimulus": "c1", "criterion": "realism",
    ...                    "condition": ["A", "B", "C"], "rank": [1, 2, 5]})
    >>> validate_results(df)
    Traceback (most recent call last):
    ...
    results_analysis.errors.AnalysisInputError: <data frame>: row 3, column 'rank': rank 5 is outside 1..3 (3 conditions)
    """
    return check_complete(validate_structure(df), incomplete=incomplete)


def _where(df: pd.DataFrame) -> pd.Series:
    if "_where" in df.columns:
        return df["_where"]
    return pd.Series([f"row {i + 1}" for i in range(len(df))], index=df.index)


def validate_structure(df: pd.DataFrame) -> pd.DataFrame:
    """Columns, ranks (numbers within range), duplicates and design hashes of the rank rows (a table with
    other paradigms' blocks is checked on its ``rank`` rows, which are what it returns); see
    :func:`validate_results`."""
    return validated_codes(df)[0]


def validated_codes(df: pd.DataFrame) -> tuple[pd.DataFrame, FrameCodes | None]:
    """:func:`validate_structure`, and the checked frame's codes (:mod:`results_analysis.codes`, factorized
    once here for the checks and handed on to the rest of an analysis; None when a key value is missing)."""
    from results_analysis.paradigms import rank_rows

    df = rank_rows(df)
    src = df.attrs.get("source")
    missing = [c for c in REQUIRED_COLUMNS if c not in df.columns]
    if missing:
        raise AnalysisInputError(src, f"column(s) {', '.join(missing)}", "missing required column(s)")
    where = _where(df)
    if df.empty:
        raise AnalysisInputError(src, None, "no rows")
    rank = pd.to_numeric(df["rank"], errors="coerce")
    if rank.isna().any():
        i = int(np.argmax(rank.isna().to_numpy()))
        raise AnalysisInputError(src, f"{where.iloc[i]}, column 'rank'", "missing or non-numeric rank")

    key = trial_key(df)
    try:
        frame = frame_codes(df, rank.to_numpy(dtype=float))
    except TypeError:  # values that do not sort (a frame not normalized): pandas' own grouping below
        frame = None
    frame = frame if frame is not None and frame.complete() else None
    codes = _frame_key(frame, 4) if frame is not None else None
    dup = pd.Series(_sizes(codes) > 1, index=df.index) if codes is not None else \
        df.duplicated(key + ["criterion", "condition"], keep=False)
    if dup.any():
        first = df.loc[dup].iloc[0]
        same = dup & (df["participant"] == first["participant"]) & (df["trial_index"] == first["trial_index"]) \
            & (df["criterion"] == first["criterion"]) & (df["condition"] == first["condition"])
        rows = " and ".join(where[same].tolist()[:3])
        raise AnalysisInputError(src, rows, f"duplicated answer: participant {first['participant']}, trial "
                                 f"{_fmt(first['trial_index'])}, criterion {first['criterion']}, condition "
                                 f"{first['condition']} appears more than once")

    rated = rated_mask(df)
    k_rated = int(frame.present("condition", rated.to_numpy()).size) if frame is not None else \
        int(df.loc[rated, "condition"].nunique())
    # Rated trials: 1..k over the study's conditions; other trials: 1..(conditions shown in that trial).
    per_trial = _sizes(codes[:-1]) if codes is not None else \
        df.groupby(key + ["criterion"], sort=False)["condition"].transform("size")
    bound = np.where(rated, max(k_rated, 1), per_trial)
    bad = (rank < 1) | (rank > bound)
    if bad.any():
        i = int(np.argmax(bad.to_numpy()))
        raise AnalysisInputError(src, f"{where.iloc[i]}, column 'rank'",
                                 f"rank {_fmt(rank.iloc[i])} is outside 1..{bound[i]} ({bound[i]} conditions)")

    if "design_hash" in df.columns:
        hashes = design_hashes(df)
        if len(hashes) > 1:
            per = df.groupby("design_hash")["participant"].nunique()
            detail = ", ".join(f"{h} ({per[h]} participant{'s' if per[h] != 1 else ''})" for h in hashes)
            warnings.warn(f"{src or '<data frame>'}: column 'design_hash': results mix {len(hashes)} study "
                          f"designs: {detail}", MixedDesignWarning, stacklevel=4)
    return df, frame


def _frame_key(frame: FrameCodes, n: int) -> list[tuple[np.ndarray, int]] | None:
    """What :func:`_codes` gives for the first ``n`` of participant, trial_index, criterion, condition, from a
    frame's codes (other codes, the same groups)."""
    cols = [(frame.participant, frame.participants), (frame.trial, frame.trials),
            (frame.criterion, frame.criteria), (frame.condition, frame.conditions)][:n]
    out, span = [], 1
    for code, uniques in cols:
        span *= max(len(uniques), 1)
        if span >= 2 ** 62:
            return None
        out.append((code, max(len(uniques), 1)))
    return out


def check_complete(df: pd.DataFrame, *, incomplete: str = "error") -> pd.DataFrame:
    """Every rated trial must rank every condition on each criterion; ``incomplete='drop'`` instead removes
    the incomplete trial-criterion blocks (listwise deletion) and records how many in
    ``attrs['dropped_incomplete']``; ``incomplete='skillings-mack'`` keeps them (counted in
    ``attrs['incomplete_blocks']``) for the Skillings-Mack test."""
    return complete_codes(df, None, incomplete=incomplete)[0]


def complete_codes(df: pd.DataFrame, frame: FrameCodes | None, *, incomplete: str = "error",
                   ) -> tuple[pd.DataFrame, FrameCodes | None]:
    """:func:`check_complete` with the frame's codes (:mod:`results_analysis.codes`; None: factorized here),
    and the codes of the frame it returns."""
    if incomplete not in INCOMPLETE_MODES:
        raise ValueError(f"incomplete must be one of {INCOMPLETE_MODES}")
    src = df.attrs.get("source")
    where = _where(df)
    rated = rated_mask(df)
    if frame is not None:
        conditions = sorted(frame.conditions[frame.present("condition", rated.to_numpy())])
    else:
        conditions = sorted(df.loc[rated, "condition"].unique())
    k = len(conditions)
    key = trial_key(df)
    codes = _frame_key(frame, 3) if frame is not None else _codes(df, key + ["criterion"])
    counts = _sizes(codes) if codes is not None else \
        df.groupby(key + ["criterion"], sort=False)["condition"].transform("size")
    short = rated & (counts < k)
    attrs = dict(df.attrs)
    if short.any():
        if incomplete == "skillings-mack":
            df.attrs["incomplete_blocks"] = int(df.loc[short, key + ["criterion"]].drop_duplicates().shape[0])
            df.attrs["dropped_incomplete"] = 0
            return df, frame
        if incomplete == "drop":
            n_dropped = int(df.loc[short, key + ["criterion"]].drop_duplicates().shape[0])
            df = df.loc[~short].copy()
            df.attrs.update(attrs)
            df.attrs["dropped_incomplete"] = n_dropped
            return df, (frame.take(~short.to_numpy()) if frame is not None else None)
        i = int(np.argmax(short.to_numpy()))
        row = df.iloc[i]
        have = set(df.loc[(df[key + ["criterion"]] == row[key + ["criterion"]]).all(axis=1), "condition"])
        lacks = ", ".join(sorted(set(conditions) - have))
        raise AnalysisInputError(src, f"{where.iloc[i]} (participant {row['participant']}, trial "
                                 f"{_fmt(row['trial_index'])}, criterion {row['criterion']})",
                                 f"the trial does not rank every condition: {lacks} missing "
                                 "(use --incomplete drop for listwise deletion or --incomplete skillings-mack)")
    df.attrs["dropped_incomplete"] = 0
    return df, frame


def _codes(df: pd.DataFrame, cols: list[str]) -> list[tuple[np.ndarray, int]] | None:
    """Each column's codes and number of distinct values, factorized once for the checks that group by them;
    None when a value is missing or the combined key could overflow (pandas' own grouping decides then)."""
    out, span = [], 1
    for c in cols:
        code, uniques = pd.factorize(df[c])
        span *= max(len(uniques), 1)
        if span >= 2 ** 62 or (code < 0).any():
            return None
        out.append((code, max(len(uniques), 1)))
    return out


def _combined(codes: list[tuple[np.ndarray, int]]) -> tuple[np.ndarray, int]:
    """One lexicographic int64 code per row from the columns' codes, and the number of possible codes."""
    key = np.zeros(len(codes[0][0]), dtype=np.int64)
    span = 1
    for code, n in codes:
        key = key * n + code
        span *= n
    return key, span


def _sizes(codes: list[tuple[np.ndarray, int]]) -> np.ndarray:
    """Per row, the number of rows with the same values in the columns of ``codes``: what
    ``groupby(cols).transform("size")`` gives, from codes factorized once."""
    key, span = _combined(codes)
    if span <= 4 * len(key) + 4096:  # few possible keys (a study's design): counted directly, no hashing
        return np.bincount(key, minlength=span)[key]
    group, _ = pd.factorize(key)
    return np.bincount(group)[group]


def distinct_rows(df: pd.DataFrame, cols: list[str]) -> int:
    """``df[cols].drop_duplicates().shape[0]``: the number of distinct combinations, from codes factorized once
    per column and counted over their few possible keys (a study's trials) where that is possible.

    >>> distinct_rows(pd.DataFrame({"p": ["a", "a", "b"], "t": [0.0, 0.0, 0.0]}), ["p", "t"])
    2
    """
    codes = _codes(df, cols) if len(df) else None
    if codes is None:
        return int(df[cols].drop_duplicates().shape[0])
    key, span = _combined(codes)
    if span <= 4 * len(key) + 4096:
        return int(np.count_nonzero(np.bincount(key, minlength=span)))
    return int(pd.unique(key).size)


def _fmt(v) -> str:
    f = float(v)
    return str(int(f)) if f.is_integer() else f"{f:g}"
