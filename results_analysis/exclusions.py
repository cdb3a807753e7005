"""Who and what is left out of the analysis, and why.

Practice trials are always out. Attention-check trials are catch trials, not comparisons, so they are out
of the rank statistics too; with ``exclude_failed_attention`` every participant who failed one is out.
Participants can also be excluded by name.
"""
from __future__ import annotations

from collections.abc import Iterable

import numpy as np
import pandas as pd

from results_analysis.codes import FrameCodes
from results_analysis.validate import trial_key


def apply_exclusions(df: pd.DataFrame, *, exclude_failed_attention: bool = False,
                     exclude: Iterable[str] = ()) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Return the analysed rows and a table of the excluded participants (participant, reason).

    >>> import pandas as pd
    >>> df = pd.DataFrame({"participant": ["P1", "P1", "P2", "P2"], "trial_index": [0, 1, 0, 1],
    ...     "is_practice": [True, False, False, False], "is_attention_check": [False, False, True, False],
    ...     "attention_passed": [True, True, False, True]})
    >>> kept, who = apply_exclusions(df, exclude_failed_attention=True)
    >>> kept["participant"].tolist(), who.to_dict("records")
    (['P1'], [{'participant': 'P2', 'reason': 'failed 1 of 1 attention check(s)'}])
    """
    kept, table, _ = excluded_rows(df, None, exclude_failed_attention=exclude_failed_attention, exclude=exclude)
    return kept, table


def excluded_rows(df: pd.DataFrame, frame: FrameCodes | None, *, exclude_failed_attention: bool = False,
                  exclude: Iterable[str] = ()) -> tuple[pd.DataFrame, pd.DataFrame, np.ndarray]:
    """:func:`apply_exclusions` with the frame's codes (:mod:`results_analysis.codes`; None: the participants
    are factorized here), and the mask of the rows kept."""
    attrs = dict(df.attrs)
    exclude = [str(p).strip() for p in exclude if str(p).strip()]
    reasons: dict[str, list[str]] = {}
    # per distinct participant, not per row: a large study has a million rows and ten thousand participants
    codes, names = (pd.factorize(df["participant"], use_na_sentinel=True) if frame is None else
                    (frame.participant, frame.participants))
    names = [str(p) for p in names]
    known = set(names)
    for p in exclude:
        reasons.setdefault(p, []).append("excluded by name (--exclude)" if p in known
                                         else "excluded by name (--exclude), but has no answers")
    checks = _checks(df) if "is_attention_check" in df.columns else df.iloc[:0]
    if len(checks):
        # One verdict per attention-check trial: a trial failed when any of its rows says so.
        per_trial = checks.groupby(trial_key(checks))["attention_passed"].all().reset_index()
        summary = per_trial.groupby("participant")["attention_passed"].agg(["size", "sum"])
        if exclude_failed_attention:
            size, passed = summary["size"].to_numpy(), summary["sum"].to_numpy()
            for i in np.flatnonzero(size - passed):
                reasons.setdefault(str(summary.index[i]), []).append(
                    f"failed {int(size[i] - passed[i])} of {int(size[i])} attention check(s)")
    named = np.array([p in reasons for p in names] + [False], dtype=bool)  # code -1 (missing): last entry
    out = pd.Series(named[codes], index=df.index)
    if "is_practice" in df.columns:
        out |= df["is_practice"].astype(bool)
    if "is_attention_check" in df.columns:
        out |= df["is_attention_check"].astype(bool)
    keep = ~out.to_numpy()
    kept = df.loc[keep]  # a new frame already (copy-on-write): no second copy of every column
    kept.attrs.update(attrs)
    kept.attrs["n_practice_rows"] = int(df["is_practice"].astype(bool).sum()) if "is_practice" in df.columns else 0
    table = pd.DataFrame([{"participant": p, "reason": "; ".join(r)} for p, r in sorted(reasons.items())],
                         columns=["participant", "reason"])
    return kept, table, keep


def attention_summary(df: pd.DataFrame) -> pd.DataFrame:
    """Per participant: attention-check trials seen and failed (empty when there are none)."""
    if "is_attention_check" not in df.columns or not df["is_attention_check"].any():
        return pd.DataFrame(columns=["participant", "checks", "failed"])
    checks = _checks(df)
    per_trial = checks.groupby(trial_key(checks))["attention_passed"].all().reset_index()
    s = per_trial.groupby("participant")["attention_passed"].agg(checks="size", passed="sum").reset_index()
    s["failed"] = s["checks"] - s["passed"]
    return s[["participant", "checks", "failed"]]


def _checks(df: pd.DataFrame) -> pd.DataFrame:
    """The attention-check rows, with only the columns their verdicts read (a copy of every column of a
    large study's checks would be most of the work)."""
    cols = [c for c in dict.fromkeys([*trial_key(df), "attention_passed"]) if c in df.columns]
    return df.loc[df["is_attention_check"].astype(bool).to_numpy(), cols]
