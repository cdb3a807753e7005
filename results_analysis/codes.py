"""The key columns of a tidy results frame as integer codes, factorized once per analysis.

A large study's frame holds a million text cells per column; hashing them again for each check, exclusion,
criterion and breakdown was most of an analysis. :func:`frame_codes` factorizes participant, trial_index,
criterion and condition once (participants and trial numbers sorted, so a trial's code orders trials as
sorting by participant and trial_index does), and :meth:`FrameCodes.take` follows the frame when rows are
left out: the distinct values stay those of the whole frame, so a subset's codes keep their order (some
values may no longer occur; :meth:`FrameCodes.present` names those that do).

The codes are handed along explicitly with the frame they were made from, never looked up by the frame's
identity: a frame changed in place cannot be paired with stale codes.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd


@dataclass(frozen=True)
class FrameCodes:
    """Each row's code among the distinct values of a column (-1 where the value is missing).

    participant, trial: codes among ``participants`` / ``trials`` (the distinct values, sorted);
    criterion, condition: codes among ``criteria`` / ``conditions`` (in order of first appearance);
    rank: each row's answer as float (NaN where missing).
    """

    participant: np.ndarray
    participants: np.ndarray
    trial: np.ndarray
    trials: np.ndarray
    criterion: np.ndarray
    criteria: np.ndarray
    condition: np.ndarray
    conditions: np.ndarray
    rank: np.ndarray

    def take(self, rows: np.ndarray) -> FrameCodes:
        """The codes of the rows selected by ``rows`` (a boolean mask or positions), same distinct values."""
        return FrameCodes(participant=self.participant[rows], participants=self.participants,
                          trial=self.trial[rows], trials=self.trials, criterion=self.criterion[rows],
                          criteria=self.criteria, condition=self.condition[rows], conditions=self.conditions,
                          rank=self.rank[rows])

    def complete(self) -> bool:
        """No key value is missing (every code >= 0)."""
        return all(not (c < 0).any() for c in (self.participant, self.trial, self.criterion, self.condition))

    def trial_keys(self) -> tuple[np.ndarray, int]:
        """Each row's (participant, trial_index) as one code (participant major) and the number of codes."""
        n_t = max(len(self.trials), 1)
        return self.participant.astype(np.int64) * n_t + self.trial, max(len(self.participants), 1) * n_t

    def present(self, column: str, rows: np.ndarray | None = None) -> np.ndarray:
        """The codes of ``column`` ('participant', 'trial', 'criterion' or 'condition') that occur (in the
        ``rows`` selected, default all), in order of first appearance."""
        codes = getattr(self, column)
        codes = codes if rows is None else codes[rows]
        codes = codes[codes >= 0]
        seen = np.flatnonzero(np.bincount(codes, minlength=1))  # counted, not sorted: few distinct values
        if seen.size > 64:
            _, first = np.unique(codes, return_index=True)
            return codes[np.sort(first)]
        first = np.array([np.argmax(codes == c) for c in seen], dtype=np.int64)
        return seen[np.argsort(first)]

    def n_present(self, column: str) -> int:
        """How many distinct values of ``column`` occur (missing ones not counted)."""
        codes = getattr(self, column)
        return int(np.count_nonzero(np.bincount(codes[codes >= 0], minlength=1)))


def frame_codes(df: pd.DataFrame, rank: np.ndarray | None = None) -> FrameCodes:
    """:class:`FrameCodes` of ``df`` (columns participant, trial_index, criterion, condition and, unless
    ``rank`` gives the answers as numbers, rank)."""
    p, pu = pd.factorize(df["participant"], sort=True)
    t, tu = pd.factorize(df["trial_index"], sort=True)
    c, cu = pd.factorize(df["criterion"])
    k, ku = pd.factorize(df["condition"])
    return FrameCodes(participant=p, participants=np.asarray(pu, dtype=object), trial=t, trials=np.asarray(tu),
                      criterion=c, criteria=np.asarray(cu, dtype=object), condition=k,
                      conditions=np.asarray(ku, dtype=object),
                      rank=df["rank"].to_numpy(dtype=float) if rank is None else np.asarray(rank, dtype=float))
