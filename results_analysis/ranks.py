"""From tidy answers to a blocks x conditions matrix of within-block ranks.

A trial (participant x stimulus) ranks every condition once. Its answers are first turned into average
ranks within the trial, so a tie written 1, 1, 3 or 1.5, 1.5, 3 becomes 1.5, 1.5, 3 before anything is
computed: no statistic depends on how ties were written.

* ``block='participant'`` (the primary analysis): one block per participant, valued by that participant's
  mean within-trial rank per condition (re-ranked within the participant by the Friedman test). A
  participant's trials are not independent, so only participants are independent blocks.
* ``block='trial'``: one block per trial, the analysis of published studies that treat every trial as an
  independent block (pseudo-replication when a participant ranks several stimuli).

:func:`place_shares` splits a tied answer over the places it spans (half each for a two-way tie).

:func:`rank_blocks_by` gives every level of a breakdown (stimulus, speaker, participant group) its blocks
from one trials x conditions matrix per criterion, and within :func:`shared_trial_tables` (one analysis)
that matrix is built once for all of them: the same numbers as :func:`rank_blocks` on each level's rows.

:func:`criterion_table` builds a criterion's matrix from a frame's codes (:mod:`results_analysis.codes`,
factorized once per analysis and passed around explicitly) instead of factorizing a million text cells for
each criterion and breakdown. A subset's codes keep the order of the whole frame's sorted values, so the
matrix, its rows and their order are the ones the frame's own factorization gives.
"""
from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import pandas as pd
from scipy.stats import rankdata

from results_analysis.codes import FrameCodes
from results_analysis.errors import AnalysisInputError
from results_analysis.validate import rated_mask, trial_key

BLOCKS = ("participant", "trial")


@dataclass(frozen=True)
class RankBlocks:
    """Within-block values of one criterion.

    values: (n, k) each block's score per condition on the within-trial rank scale: a trial's average ranks,
        or a participant's mean of them (NaN where an incomplete trial lacks a condition).
    ranks: (n, k) ``values`` re-ranked within each block with average ranks for ties (1 = best); equal to
        ``values`` for trial blocks.
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


class CriterionTable(NamedTuple):
    """A criterion's trials x conditions matrix (see :func:`criterion_table`)."""

    rows: np.ndarray          # (rows of the frame,) bool: the criterion's rows
    n_trials: int             # trials with at least one answer
    answers: tuple            # (positions among the criterion's rows, trial of each) of the answers in the matrix
    complete: np.ndarray      # (n_trials,) bool: the trial ranks every condition
    owner: np.ndarray         # participant of each complete trial
    values: np.ndarray        # (complete trials, k) within-trial average ranks
    #: from codes (criterion_table): each complete trial's participant code among ``participants``, which are
    #: all text (None from a frame's own columns)
    owner_codes: np.ndarray | None = None
    participants: np.ndarray | None = None


def criterion_table(codes: FrameCodes, criterion: str, conditions: list[str]) -> CriterionTable:
    """The table :func:`rank_blocks_by` splits, for ``criterion`` of the frame ``codes`` were made from: the
    numbers ``_criterion_table`` gives from the frame's text columns (see module docstring)."""
    found = np.flatnonzero(codes.criteria == criterion)
    rows = codes.criterion == found[0] if found.size else np.zeros(len(codes.criterion), dtype=bool)
    key = [(codes.participant[rows], codes.participants), (codes.trial[rows], codes.trials)]
    trials, raw, n_trials, answers, trial_codes = _wide_codes(key, codes.condition[rows], codes.conditions,
                                                              codes.rank[rows], conditions)
    complete = ~np.isnan(raw).any(axis=1)
    text = len(codes.participants) and pd.api.types.infer_dtype(codes.participants, skipna=False) == "string"
    return CriterionTable(rows, n_trials, answers, complete, trials[0][complete], _trial_ranks(raw[complete]),
                          owner_codes=trial_codes[0][complete] if text else None,
                          participants=codes.participants if text else None)


def participant_index(participants: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``np.unique(participants, return_inverse=True)``: the sorted distinct participants and each block's
    index among them. Blocks come sorted by participant, so the runs are read off without sorting 80,000
    strings again (any other order is sorted by np.unique).

    >>> ids, which = participant_index(np.array(["P1", "P1", "P2"], dtype=object))
    >>> ids.tolist(), which.tolist()
    (['P1', 'P2'], [0, 0, 1])
    """
    p = np.asarray(participants)
    if p.ndim == 1 and len(p) > 1:
        try:
            ordered = bool(np.all(p[1:] >= p[:-1]))
        except TypeError:  # values that do not compare: np.unique says so
            ordered = False
        if ordered:
            first = np.r_[True, p[1:] != p[:-1]]
            return p[first], np.cumsum(first) - 1
    return np.unique(p, return_inverse=True)


def text_levels(col: pd.Series, missing: str | None = None) -> pd.Categorical:
    """``pd.Categorical(col.fillna(missing).astype(str).to_numpy(dtype=object))`` (without the fill when
    ``missing`` is None): each value's text, the distinct texts sorted, as a breakdown splits rows. A column
    of text (the usual case) is factorized as it is, without writing a million strings again first.

    >>> text_levels(pd.Series(["b", None, "a"], dtype=object), "(none)").tolist()
    ['b', '(none)', 'a']
    """
    values = col.to_numpy(dtype=object)
    kind = pd.api.types.infer_dtype(values, skipna=missing is not None)
    if kind == "string" and len(values):
        if missing is not None:
            gap = pd.isna(values)
            if gap.any():
                values = values.copy()
                values[gap] = missing
        # the same categories and codes as pd.Categorical(values), which takes twice as long over the column
        codes, uniques = pd.factorize(values, sort=True)
        return pd.Categorical.from_codes(codes, categories=pd.Index(uniques))
    if missing is not None:
        col = col.fillna(missing)
    return pd.Categorical(col.astype(str).to_numpy(dtype=object))


def ties(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.isclose(a, b)`` (broadcast), by plain equality where that is the same answer: ranks that are all
    finite multiples of 1/2 below 1,000 differ by at least 1/2 when they differ, far beyond isclose's
    tolerance (1e-8 + 1e-5 |b|), so equal is close. Other values go to isclose."""
    if _half_steps(a) and _half_steps(b):
        return a == b
    return np.isclose(a, b)


def _half_steps(x: np.ndarray) -> bool:
    """Every value of ``x`` (at least one) is a finite multiple of 1/2 below 1,000 in magnitude: such values are
    isclose exactly when they are equal (see :func:`ties`)."""
    x = np.ravel(x)
    if not x.size or not np.isfinite(x).all() or np.abs(x).max() >= 1000:
        return False
    twice = x * 2
    return bool((twice == np.floor(twice)).all())


def tie_sizes(r: np.ndarray) -> np.ndarray:
    """(n, k) int: how many cells of its row each cell of ``r`` ties with (itself included), as
    ``ties(r[:, :, None], r[:, None, :]).sum(axis=2)``; for half-step ranks by comparing two columns at a
    time (k^2 passes over n cells instead of a sum along the short last axis of an (n, k, k) cube)."""
    n, k = r.shape
    if k > 6 or not _half_steps(r):
        return ties(r[:, :, None], r[:, None, :]).sum(axis=2)
    cols = [np.ascontiguousarray(r[:, j]) for j in range(k)]
    out = np.empty((n, k), dtype=np.int64)
    for i in range(k):
        size = np.ones(n, dtype=np.int64)
        for j in range(k):
            if j != i:
                size += cols[j] == cols[i]
        out[:, i] = size
    return out


def within_block_ranks(values: np.ndarray) -> np.ndarray:
    """Average ranks within each row (1 = smallest): ties share the mean of the ranks they span.

    >>> within_block_ranks(np.array([[1, 1, 3], [3.0, 1.0, 2.0]])).tolist()
    [[1.5, 1.5, 3.0], [3.0, 1.0, 2.0]]
    """
    return _row_ranks(np.asarray(values, dtype=float))


def _row_ranks(x: np.ndarray) -> np.ndarray:
    """``rankdata(x, axis=1, method="average")``, the same numbers: for the few conditions of a study, by
    comparing each cell with the others in its row (a cell with L smaller and t equal cells, itself included,
    has the average rank L + (t + 1) / 2, exact in floating point) instead of sorting every row. A row with
    NaN, or a very wide matrix, goes to rankdata."""
    if x.ndim != 2 or x.shape[1] > 16 or not x.size or np.isnan(x).any():
        return rankdata(x, axis=1, method="average")
    k = x.shape[1]
    if k > 6:
        a, b = x[:, :, None], x[:, None, :]
        return (b < a).sum(axis=2) + ((b == a).sum(axis=2) + 1) / 2.0
    # a few conditions: one comparison of two columns at a time, k^2 passes over n cells, not sums along the
    # short last axis of an (n, k, k) cube (4x slower for the hundreds of thousands of rows of a large study)
    cols = [np.ascontiguousarray(x[:, j]) for j in range(k)]
    out = np.empty(x.shape)
    for i in range(k):
        smaller = np.zeros(len(x), dtype=np.int64)
        equal = np.ones(len(x), dtype=np.int64)  # the cell itself
        for j in range(k):
            if j != i:
                smaller += cols[j] < cols[i]
                equal += cols[j] == cols[i]
        out[:, i] = smaller + (equal + 1) / 2.0
    return out


def rank_blocks(df: pd.DataFrame, criterion: str, *, block: str = "participant",
                conditions: list[str] | None = None, complete_only: bool = True) -> RankBlocks:
    """Build the blocks x conditions rank matrix of one criterion from a validated tidy frame.

    >>> import pandas as pd
    >>> df = pd.DataFrame({"participant": ["P1"] * 3 + ["P2"] * 3, "trial_index": 0, "stimulus": "c1",
    ...                    "criterion": "realism", "condition": list("ABC") * 2, "rank": [1, 2, 3, 2, 1, 3]})
    >>> rank_blocks(df, "realism", block="trial").ranks.tolist()
    [[1.0, 2.0, 3.0], [2.0, 1.0, 3.0]]
    """
    if block not in BLOCKS:
        raise ValueError(f"block must be one of {BLOCKS}, not {block!r}")
    if block == "participant" and not complete_only:
        # an incomplete trial's ranks run over fewer places: they cannot be averaged with complete ones
        raise ValueError("incomplete blocks are kept for trial blocks only (the Skillings-Mack test)")
    key = trial_key(df)
    # only the columns the matrix needs are copied (a large study's frame has millions of cells)
    sub = df.loc[df["criterion"].to_numpy(dtype=object) == criterion, [*key, "condition", "rank"]]
    if conditions is None:
        conditions = sorted(df["condition"].unique())
    trials, raw, _, _ = _wide(sub, key, list(conditions))
    # Blocks that lack a condition are dropped (listwise deletion) unless ``complete_only`` is false, for
    # the Skillings-Mack test, which reads the NaNs; validation decides whether incomplete blocks may exist.
    if complete_only:
        complete = ~np.isnan(raw).any(axis=1)
        trials, raw = [t[complete] for t in trials], raw[complete]
    return _blocks(trials[0], _trial_ranks(raw), list(conditions), block, complete_only)


def rank_blocks_by(df: pd.DataFrame, criterion: str, levels: pd.Series | np.ndarray | pd.Categorical, *,
                   block: str = "participant", conditions: list[str]) -> dict[str, tuple[RankBlocks, RankBlocks]]:
    """Per distinct value of ``levels`` (one per row of ``df``, sorted; or each category of a Categorical): the
    blocks at ``block`` and the trial blocks of ``criterion`` in the rows of that level, complete trials only:
    what ``rank_blocks`` gives for ``df[levels == level]`` with ``block=block`` and with ``block='trial'``,
    built from one trials x conditions matrix instead of two per level (a breakdown by stimulus or speaker).

    A trial whose answers lie in two levels is incomplete in each (in a validated frame, without duplicated
    answers): should one exist, every level is computed on its own rows, as ``rank_blocks`` would.

    >>> import pandas as pd
    >>> df = pd.DataFrame({"participant": ["P1"] * 6, "trial_index": [0, 0, 0, 1, 1, 1], "criterion": "realism",
    ...                    "condition": list("ABC") * 2, "rank": [1, 2, 3, 3, 2, 1], "stimulus": ["c1"] * 3 + ["c2"] * 3})
    >>> {lv: b.ranks.tolist() for lv, (b, _) in rank_blocks_by(df, "realism", df["stimulus"], conditions=list("ABC")).items()}
    {'c1': [[1.0, 2.0, 3.0]], 'c2': [[3.0, 2.0, 1.0]]}
    """
    if block not in BLOCKS:
        raise ValueError(f"block must be one of {BLOCKS}, not {block!r}")
    return split_table(df, criterion, _criterion_table(df, criterion, list(conditions)), levels, block=block,
                       conditions=conditions)


def split_table(df: pd.DataFrame, criterion: str, table: CriterionTable,
                levels: pd.Series | np.ndarray | pd.Categorical, *, block: str = "participant",
                conditions: list[str]) -> dict[str, tuple[RankBlocks, RankBlocks]]:
    """:func:`rank_blocks_by` with the criterion's ``table`` given (from :func:`criterion_table`)."""
    if not isinstance(levels, pd.Categorical):  # a breakdown's caller may pass one: factorized once for all criteria
        levels = pd.Categorical(np.asarray(levels, dtype=object))
    level_codes, names = levels.codes, levels.categories
    rows, n_trials, (answer, trial), complete, owner, values = table[:6]
    of_answer = level_codes[rows][answer]
    level = np.full(n_trials, -1, dtype=np.int64)
    level[trial] = of_answer  # one of each trial's codes (the last written) ...
    level[trial[level[trial] != of_answer]] = -1  # ... and -1 where another answer of the trial has another
    # an incomplete trial is incomplete in every level's rows too: only a complete trial's level matters
    level = level[complete]
    if (level < 0).any():  # a complete trial split between levels (duplicated answers): each level
        out = {}  # on its own rows, as rank_blocks would
        for name in names:
            part = df[levels == name]
            b = rank_blocks(part, criterion, block=block, conditions=conditions)
            out[str(name)] = (b, b if block == "trial" else rank_blocks(part, criterion, block="trial",
                                                                        conditions=conditions))
        return out
    out = {}
    for code, name in enumerate(names):
        mine = level == code
        if table.owner_codes is not None and mine.any():  # participants as codes: no comparison of their texts
            oc, v = table.owner_codes[mine], values[mine]
            tb = _code_blocks(oc, table.participants, v, list(conditions), "trial")
            out[str(name)] = (tb if block == "trial" else _code_blocks(oc, table.participants, v, list(conditions),
                                                                       block), tb)
            continue
        tb = _blocks(owner[mine], values[mine], list(conditions), "trial", True)
        out[str(name)] = (tb if block == "trial" else _blocks(owner[mine], values[mine], list(conditions), block,
                                                              True), tb)
    return out


def rank_blocks_with_trials(df: pd.DataFrame, criterion: str, *, block: str = "participant",
                            conditions: list[str]) -> tuple[RankBlocks, RankBlocks]:
    """``rank_blocks`` at ``block`` and at ``'trial'`` (complete trials), from one trials x conditions matrix.

    >>> import pandas as pd
    >>> df = pd.DataFrame({"participant": ["P1"] * 6, "trial_index": [0, 0, 0, 1, 1, 1], "criterion": "realism",
    ...                    "condition": list("ABC") * 2, "rank": [1, 2, 3, 3, 2, 1]})
    >>> b, t = rank_blocks_with_trials(df, "realism", conditions=list("ABC"))
    >>> b.values.tolist(), t.n
    ([[2.0, 2.0, 2.0]], 2)
    """
    if len(df):
        one_level = pd.Categorical.from_codes(np.zeros(len(df), dtype=np.int8), categories=["all"])
        return rank_blocks_by(df, criterion, one_level, block=block, conditions=conditions)["all"]
    return _empty_with_trials(df, criterion, block=block, conditions=conditions)


def table_with_trials(df: pd.DataFrame, criterion: str, table: CriterionTable, *, block: str = "participant",
                      conditions: list[str]) -> tuple[RankBlocks, RankBlocks]:
    """:func:`rank_blocks_with_trials` with the criterion's ``table`` given (from :func:`criterion_table`)."""
    if block not in BLOCKS:
        raise ValueError(f"block must be one of {BLOCKS}, not {block!r}")
    if len(df):
        one_level = pd.Categorical.from_codes(np.zeros(len(df), dtype=np.int8), categories=["all"])
        return split_table(df, criterion, table, one_level, block=block, conditions=conditions)["all"]
    return _empty_with_trials(df, criterion, block=block, conditions=conditions)


def _empty_with_trials(df: pd.DataFrame, criterion: str, *, block: str,
                       conditions: list[str]) -> tuple[RankBlocks, RankBlocks]:
    b = rank_blocks(df, criterion, block=block, conditions=conditions)
    return b, b if block == "trial" else rank_blocks(df, criterion, block="trial", conditions=conditions)


#: (id of the frame, criterion, conditions) -> (the frame, its table); set only inside :func:`shared_trial_tables`.
_TABLES: ContextVar[dict | None] = ContextVar("results_analysis_trial_tables", default=None)


@contextmanager
def shared_trial_tables() -> Iterator[None]:
    """Within this block each criterion's trials x conditions matrix of a frame is built once, for every
    breakdown that splits it (:func:`rank_blocks_by`): the frame must not change inside the block."""
    if _TABLES.get() is not None:
        yield
        return
    token = _TABLES.set({})
    try:
        yield
    finally:
        _TABLES.reset(token)


def _criterion_table(df: pd.DataFrame, criterion: str, conditions: list[str]) -> CriterionTable:
    """The rows of ``criterion`` (mask), the number of trials, the answers the matrix holds (positions among
    those rows, trial of each), which trials are complete, and their participants and within-trial ranks."""
    cache = _TABLES.get()
    tag = (id(df), criterion, tuple(conditions))
    if cache is not None and tag in cache and cache[tag][0] is df:
        return cache[tag][1]
    key = trial_key(df)
    rows = df["criterion"].to_numpy(dtype=object) == criterion
    trials, raw, n_trials, answers = _wide(df.loc[rows, [*key, "condition", "rank"]], key, conditions)
    complete = ~np.isnan(raw).any(axis=1)
    table = CriterionTable(rows, n_trials, answers, complete, trials[0][complete], _trial_ranks(raw[complete]))
    if cache is not None:
        cache[tag] = (df, table)  # the frame is kept with it: its id cannot be reused while the block lasts
    return table


def _trial_ranks(raw: np.ndarray) -> np.ndarray:
    """Within-trial average ranks of a trials x conditions matrix of answers (NaN stays NaN): the tie coding
    (1,1,3 or 1.5,1.5,3) is gone from here on."""
    if not raw.size:
        return raw
    missing = np.isnan(raw)
    return np.where(missing, np.nan, _row_ranks(np.where(missing, np.inf, raw)))


def _blocks(owner: np.ndarray, values: np.ndarray, conditions: list[str], block: str,
            complete_only: bool) -> RankBlocks:
    """The blocks of trials sorted by participant (``owner``: each trial's participant; ``values``: its
    within-trial ranks)."""
    if block == "participant":
        # a participant's mean of its trials' ranks (trials are sorted by participant); the sums of average
        # ranks (multiples of 1/2) are exact, so this is the number a pandas group mean gives
        first = np.flatnonzero(np.r_[True, owner[1:] != owner[:-1]]) if len(owner) else np.zeros(0, dtype=int)
        per = np.diff(np.r_[first, len(owner)])
        owner = owner[first]
        values = np.add.reduceat(values, first, axis=0) / per[:, None] if len(values) else values
    # participant ids as text (a normalized frame's already are: no conversion of 10,000 strings per block)
    participants = owner if owner.dtype == object and len(owner) and \
        pd.api.types.infer_dtype(owner, skipna=False) == "string" else pd.Index(owner).astype(str).to_numpy()
    ranks = values
    if len(values) and block == "participant":
        ranks = within_block_ranks(values) if complete_only else np.where(
            np.isnan(values), np.nan, _row_ranks(np.where(np.isnan(values), np.inf, values)))
    return RankBlocks(values=values, ranks=ranks, conditions=list(conditions), participants=participants,
                      block=block)


def _code_blocks(owner: np.ndarray, participants: np.ndarray, values: np.ndarray, conditions: list[str],
                 block: str) -> RankBlocks:
    """:func:`_blocks` of complete trials (at least one) whose participants are given as codes (``owner``, sorted)
    among ``participants`` (all text): the same blocks, the runs of a participant's trials found by comparing
    integers, not texts."""
    if block == "participant":
        first = np.flatnonzero(np.r_[True, owner[1:] != owner[:-1]])
        per = np.diff(np.r_[first, len(owner)])
        owner = owner[first]
        values = np.add.reduceat(values, first, axis=0) / per[:, None]
    ranks = within_block_ranks(values) if block == "participant" else values
    return RankBlocks(values=values, ranks=ranks, conditions=list(conditions), participants=participants[owner],
                      block=block)


def _wide(sub: pd.DataFrame, key: list[str], conditions: list[str],
          ) -> tuple[list[np.ndarray], np.ndarray, int, tuple[np.ndarray, np.ndarray]]:
    """The trials x conditions matrix of ranks that ``sub.pivot_table(index=key, columns="condition",
    values="rank", aggfunc="first", observed=True).reindex(columns=conditions)`` gives, without pandas' group
    machinery (a 10,000-participant study builds dozens of these): trials sorted by ``key``, each trial's
    first non-missing rank per condition, trials with no rank at all (in any condition) left out.

    Returns the trials' key values (one array per key column, aligned with the rows), the matrix, the number
    of trials and the answers it was built from: their positions in ``sub`` and the trial (row) of each.
    """
    rank = sub["rank"].to_numpy(dtype=float)
    key_codes = [pd.factorize(sub[c], sort=True) for c in key] if len(sub) else []
    cond_codes, cond_names = pd.factorize(sub["condition"], sort=True)
    return _wide_codes(key_codes, cond_codes, cond_names, rank, conditions, n_key=len(key))[:4]


def _wide_codes(key_codes: list[tuple[np.ndarray, np.ndarray]], cond_codes: np.ndarray, cond_names,
                rank: np.ndarray, conditions: list[str], n_key: int = 2) -> tuple:
    """:func:`_wide` from the rows' codes: per key column (codes, distinct values sorted), the conditions'
    codes and names, and the ranks. Any sorted distinct values that include the rows' give the same matrix:
    only the order of the codes matters. After what _wide returns comes each trial's code per key column."""
    codes, uniques = zip(*key_codes) if key_codes else ((), ())
    ok = ~np.isnan(rank) & (cond_codes >= 0)
    for c in codes:
        ok &= c >= 0
    trial = np.zeros(len(rank), dtype=np.int64)
    for c, u in zip(codes, uniques):  # lexicographic code of the key, in the key's sort order
        trial = trial * max(len(u), 1) + c
    rows, row_of = _sorted_distinct(trial[ok], int(np.prod([max(len(u), 1) for u in uniques])))
    column = {name: i for i, name in enumerate(conditions)}
    col_of = np.array([column.get(name, -1) for name in cond_names], dtype=np.int64)[cond_codes[ok]] \
        if len(cond_names) else np.zeros(0, dtype=np.int64)
    out = np.full((rows.size, len(conditions)), np.nan)
    inside = col_of >= 0
    cell = row_of[inside] * len(conditions) + col_of[inside]
    if np.bincount(cell, minlength=out.size).max(initial=0) <= 1:  # one answer per trial x condition (as
        out.flat[cell] = rank[ok][inside]  # validated): no first answer to pick, no sort of the cells
    else:
        _, first = np.unique(cell, return_index=True)  # the first answer of each trial x condition
        out.flat[cell[first]] = rank[ok][inside][first]
    n_trials, answers = rows.size, (np.flatnonzero(ok)[inside], row_of[inside])
    keys, key_codes = [], []
    for c, u in zip(codes[::-1], uniques[::-1]):  # undo the lexicographic code, last column first
        size = max(len(u), 1)
        key_codes.append(rows % size)
        keys.append(np.asarray(u)[key_codes[-1]])
        rows = rows // size
    keys = keys[::-1] or [np.zeros(0, dtype=object) for _ in range(n_key)]
    return keys, out, n_trials, answers, key_codes[::-1]


def _sorted_distinct(codes: np.ndarray, span: int) -> tuple[np.ndarray, np.ndarray]:
    """``np.unique(codes, return_inverse=True)`` for non-negative codes below ``span``: by marking the codes
    present when ``span`` is small (trials of a study's participants and trial numbers), not by sorting them."""
    if span > 4 * codes.size + 4096:
        return np.unique(codes, return_inverse=True)
    present = np.zeros(span, dtype=bool)
    present[codes] = True
    return np.flatnonzero(present).astype(codes.dtype, copy=False), (np.cumsum(present) - 1)[codes]


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


def place_shares(ranks: np.ndarray) -> np.ndarray:
    """(k conditions, k places): the share of blocks that put each condition at each place (1 = best).

    ``ranks`` are within-block average ranks. A tied answer is shared between the places it spans: a two-way
    tie for first gives half a block to place 1 and half to place 2, a three-way tie a third to each of its
    three places. Every row and every column sums to 1, whatever the ties.

    >>> place_shares(np.array([[1.5, 1.5, 3.0], [1.0, 2.0, 3.0]])).tolist()
    [[0.75, 0.25, 0.0], [0.25, 0.75, 0.0], [0.0, 0.0, 1.0]]
    """
    r = np.asarray(ranks, dtype=float)
    n, k = r.shape
    if n == 0:
        return np.full((k, k), np.nan)
    tie_size = tie_sizes(r)                                                # (n, k): size of each cell's tie
    first = r - (tie_size - 1) / 2.0                                       # the first place a cell spans
    places = np.arange(1, k + 1, dtype=float)
    spans = (places[None, None, :] >= first[:, :, None] - 1e-9) & \
            (places[None, None, :] <= first[:, :, None] + tie_size[:, :, None] - 1 + 1e-9)
    return (spans / tie_size[:, :, None]).mean(axis=0)
