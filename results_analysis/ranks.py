"""From tidy answers to a blocks x conditions matrix of within-block ranks.

A block is whatever ranks every condition once. By default that is one trial (participant x stimulus);
with ``block='participant'`` the block is a participant and the values are that participant's mean rank
per condition (re-ranked within the participant by the Friedman test), the usual sensitivity check.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy.stats import rankdata

from results_analysis.errors import AnalysisInputError
from results_analysis.validate import rated_mask, trial_key

BLOCKS = ("trial", "participant")


@dataclass(frozen=True)
class RankBlocks:
    """Within-block values of one criterion.

    values: (n, k) what each block gave each condition (ranks, or mean ranks per participant).
    ranks: (n, k) ``values`` re-ranked within each block with average ranks for ties (1 = best).
    conditions: the k condition names, column order of both matrices.
    participants: (n,) the participant each block belongs to (for bootstraps over participants).
    block: 'trial' or 'participant'.
    """

    values: np.ndarray
    ranks: np.ndarray
    conditions: list[str]
    participants: np.ndarray
    block: str

    @property
    def n(self) -> int:
        return int(self.ranks.shape[0])

    @property
    def k(self) -> int:
        return int(self.ranks.shape[1])


def within_block_ranks(values: np.ndarray) -> np.ndarray:
    """Average ranks within each row (1 = smallest): ties share the mean of the ranks they span.

    >>> within_block_ranks(np.array([[1, 1, 3], [3.0, 1.0, 2.0]])).tolist()
    [[1.5, 1.5, 3.0], [3.0, 1.0, 2.0]]
    """
    return rankdata(np.asarray(values, dtype=float), axis=1, method="average")


def rank_blocks(df: pd.DataFrame, criterion: str, *, block: str = "trial",
                conditions: list[str] | None = None, complete_only: bool = True) -> RankBlocks:
    """Build the blocks x conditions rank matrix of one criterion from a validated tidy frame.

    >>> import pandas as pd
    >>> df = pd.DataFrame({"participant": ["P1"] * 3 + ["P2"] * 3, "trial_index": 0, "stimulus": "c1",
    ...                    "criterion": "realism", "condition": list("ABC") * 2, "rank": [1, 2, 3, 2, 1, 3]})
    >>> rank_blocks(df, "realism").ranks.tolist()
    [[1.0, 2.0, 3.0], [2.0, 1.0, 3.0]]
    """
    if block not in BLOCKS:
        raise ValueError(f"block must be one of {BLOCKS}, not {block!r}")
    sub = df[df["criterion"] == criterion]
    if conditions is None:
        conditions = sorted(df["condition"].unique())
    if block == "trial":
        key = trial_key(sub)
        wide = sub.pivot_table(index=key, columns="condition", values="rank", aggfunc="first", observed=True)
    else:
        key = ["participant"]
        wide = sub.pivot_table(index=key, columns="condition", values="rank", aggfunc="mean", observed=True)
    wide = wide.reindex(columns=conditions)
    # Blocks that lack a condition are dropped (listwise deletion) unless ``complete_only`` is false, for
    # the Skillings-Mack test, which reads the NaNs; validation decides whether incomplete blocks may exist.
    if complete_only:
        wide = wide.dropna(axis=0, how="any")
    values = wide.to_numpy(dtype=float)
    participants = wide.index.get_level_values("participant").astype(str).to_numpy()
    ranks = values
    if len(values):
        ranks = within_block_ranks(values) if complete_only else np.where(
            np.isnan(values), np.nan, rankdata(np.where(np.isnan(values), np.inf, values), axis=1, method="average"))
    return RankBlocks(values=values, ranks=ranks, conditions=list(conditions), participants=participants,
                      block=block)


def as_blocks(data: RankBlocks | pd.DataFrame, criterion: str | None = None, *, block: str = "trial") -> RankBlocks:
    """``data`` itself when it is a :class:`RankBlocks`; else the blocks of ``criterion`` in a tidy results
    frame (one row per participant x trial x criterion x condition, as ``studyapp export`` writes it).

    Practice and attention-check rows are left out, as the command-line analysis does, so a notebook that
    passes the raw export gets the same numbers. ``criterion`` may be omitted when the frame has only one.
    """
    if isinstance(data, RankBlocks):
        return data
    if not isinstance(data, pd.DataFrame):
        raise TypeError(f"expected RankBlocks or a tidy results DataFrame, not {type(data).__name__}")
    from results_analysis.loader import normalize_results  # flags written as yes/no, t/f or 0/1 become booleans

    rated = normalize_results(data)
    rated = rated[rated_mask(rated)]
    if rated.empty:
        raise AnalysisInputError(data.attrs.get("source"), None, "no rated trials: every row is a practice or "
                                 "attention-check trial")
    if criterion is None:
        found = list(dict.fromkeys(rated["criterion"]))
        if len(found) != 1:
            raise ValueError(f"the frame has criteria {found}: pass criterion=")
        criterion = found[0]
    return rank_blocks(rated, criterion, block=block, conditions=sorted(rated["condition"].unique()))
