"""What a results table says about its study besides the ranks: each condition's label and place in the
design, each criterion's label, the study's title and the participants' questionnaire answers.

``studyapp export`` writes them into every row (columns ``condition_label``, ``condition_position``,
``criterion_label``, ``study_title`` and ``questionnaire:<scale>:<item>``, see
:mod:`results_analysis.sqlite_schema`), and a database gives the same columns, so a CSV export and its
database give the same report. A table without them (an older export, a hand-made CSV) still works: its
conditions and criteria are named by their ids, the conditions in the order of the ids, and the report's
title comes from elsewhere.

The analysis keeps computing on condition ids (``stats.json`` is keyed by them); :func:`relabel` turns an
analysis into the one the tables, figures and text show, with each id replaced by its label.

>>> import pandas as pd
>>> df = pd.DataFrame({"condition": ["b", "a", "c"], "condition_label": ["Baseline", None, "Ours"],
...                    "condition_position": [0, 1, 2]})
>>> condition_order(df), condition_labels(df)
(['b', 'a', 'c'], {'b': 'Baseline', 'a': 'a', 'c': 'Ours'})
"""
from __future__ import annotations

import copy
import dataclasses
from collections.abc import Mapping
from typing import TypeVar

import numpy as np
import pandas as pd

from results_analysis.errors import AnalysisInputError
from results_analysis.sqlite_schema import QUESTIONNAIRE_PREFIX, _scale_of

T = TypeVar("T")


def first_pairs(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Positions of the first row of each distinct (a, b) pair, in row order (missing values of ``b`` count as
    one value). A check that walks the rows in order and remembers the first value seen per key meets its
    first conflict at such a row, so walking these few rows instead of a large study's every row gives the
    same answer and names the same row.

    >>> first_pairs(np.array(["A", "A", "B", "A"], dtype=object), np.array([1.0, 1.0, np.nan, 2.0])).tolist()
    [0, 2, 3]
    """
    if not len(a):
        return np.zeros(0, dtype=np.int64)
    ca, ua = pd.factorize(a)
    cb, ub = pd.factorize(b)  # a missing value is code -1
    key = (ca.astype(np.int64) + 1) * (len(ub) + 1) + (cb + 1)
    _, first = np.unique(key, return_index=True)
    return np.sort(first)


def condition_order(df: pd.DataFrame) -> list[str]:
    """The conditions of ``df`` in the design's order (``condition_position``); conditions without a
    position (or a table without the column) follow, ordered by id. Raises :class:`AnalysisInputError` when
    one condition has two positions or two conditions share one."""
    ids = sorted(df["condition"].astype(str).unique())
    if "condition_position" not in df.columns:
        return ids
    pos = pd.to_numeric(df["condition_position"], errors="coerce")
    where = df["_where"] if "_where" in df.columns else pd.Series([f"row {i + 1}" for i in range(len(df))])
    place: dict[str, float] = {}
    owner: dict[float, str] = {}
    cids = df["condition"].astype(str).to_numpy(dtype=object)
    first = first_pairs(cids, pos.to_numpy())
    for cid, p, w in zip(cids[first], pos.to_numpy()[first], where.to_numpy()[first]):
        if pd.isna(p):
            continue
        if place.setdefault(cid, p) != p:
            raise AnalysisInputError(df.attrs.get("source"), f"{w}, column 'condition_position'",
                                     f"condition {cid!r} has positions {place[cid]:g} and {p:g}; one condition "
                                     "has one place in the design")
        if owner.setdefault(p, cid) != cid:
            raise AnalysisInputError(df.attrs.get("source"), f"{w}, column 'condition_position'",
                                     f"conditions {owner[p]!r} and {cid!r} both have position {p:g}")
    return sorted(ids, key=lambda c: (c not in place, place.get(c, 0.0), c))


def condition_labels(df: pd.DataFrame, conditions: list[str] | None = None) -> dict[str, str]:
    """``{condition id: label}`` for ``conditions`` (default: :func:`condition_order`): the
    ``condition_label`` of its rows, else the id (no label recorded, or no such column). Raises
    :class:`AnalysisInputError` when one condition has two labels or two conditions would show the same name.
    """
    conditions = condition_order(df) if conditions is None else conditions
    found: dict[str, str] = {}
    if "condition_label" in df.columns:
        where = df["_where"] if "_where" in df.columns else pd.Series([f"row {i + 1}" for i in range(len(df))])
        cids, raw = df["condition"].astype(str).to_numpy(dtype=object), df["condition_label"].to_numpy(dtype=object)
        first = first_pairs(cids, raw)
        gap = np.flatnonzero(pd.isna(raw))
        if gap.size:  # a missing value other than None or NaN (pd.NA, NaT) reads as a label below: walk each
            odd = np.fromiter((not (v is None or isinstance(v, float)) for v in raw[gap]), dtype=bool, count=gap.size)
            first = np.union1d(first, gap[odd])
        for cid, label, w in zip(cids[first], raw[first], where.to_numpy()[first]):
            if label is None or (isinstance(label, float) and np.isnan(label)) or not str(label).strip():
                continue
            label = " ".join(str(label).split())  # one line: it heads table rows and figure axes
            if found.setdefault(cid, label) != label:
                raise AnalysisInputError(df.attrs.get("source"), f"{w}, column 'condition_label'",
                                         f"condition {cid!r} is labelled both {found[cid]!r} and {label!r}")
    labels = {c: found.get(c, c) for c in conditions}
    shown: dict[str, str] = {}
    for cid, label in labels.items():
        other = shown.setdefault(label.casefold(), cid)
        if other != cid:
            raise AnalysisInputError(df.attrs.get("source"), "column 'condition_label'",
                                     f"conditions {other!r} and {cid!r} would both be shown as {label!r}; "
                                     "give them different labels")
    return labels


def criterion_labels(df: pd.DataFrame) -> dict[str, str]:
    """``{criterion id: label}`` for every criterion of ``df``, in the order first seen: the
    ``criterion_label`` of its rows (the design's label, e.g. ``"Synchronization with speech"``), else the id (a
    table before schema 7, a hand-made CSV). Raises :class:`AnalysisInputError` when one criterion has two labels.

    >>> criterion_labels(pd.DataFrame({"criterion": ["sync", "real"], "criterion_label": ["In time", None]}))
    {'sync': 'In time', 'real': 'real'}
    """
    found: dict[str, str] = {}
    cids = df["criterion"].astype(str).to_numpy(dtype=object)
    ids = list(pd.unique(cids))  # in order of appearance
    if "criterion_label" in df.columns:
        labels = df["criterion_label"].to_numpy(dtype=object)
        for i in first_pairs(cids, labels):  # one look per distinct (id, label) pair, in row order
            label = labels[i]
            if label is None or (isinstance(label, float) and np.isnan(label)) or not str(label).strip():
                continue
            label = " ".join(str(label).split())  # one line: it heads paragraphs, tables and figure panels
            if found.setdefault(cids[i], label) != label:
                w = df["_where"].iloc[i] if "_where" in df.columns else f"row {i + 1}"
                raise AnalysisInputError(df.attrs.get("source"), f"{w}, column 'criterion_label'",
                                         f"criterion {cids[i]!r} is labelled both {found[cids[i]]!r} and {label!r}")
    return {c: found.get(c, c) for c in ids}


def with_criterion_label(table: pd.DataFrame, names: Mapping[str, str]) -> pd.DataFrame:
    """``table`` with a ``criterion_label`` column right after its ``criterion`` column: each criterion's name
    in ``names`` (id -> label, see :func:`criterion_labels`), else its id. ``criterion`` keeps the id, so a
    script that selects or joins on it works as before; the label sits beside it, as in the tidy export. A
    table without a ``criterion`` column, or that has a label already, is returned as it is. For every CSV
    in ``tables/`` that names criteria.

    >>> with_criterion_label(pd.DataFrame({"criterion": ["sync", "real"], "p": [0.5, 0.1]}), {"sync": "In time"})
      criterion criterion_label    p
    0      sync         In time  0.5
    1      real            real  0.1
    """
    if "criterion" not in table.columns or "criterion_label" in table.columns:
        return table
    out = table.copy()
    out.insert(out.columns.get_loc("criterion") + 1, "criterion_label",
               [names.get(c, c) for c in out["criterion"]])
    return out


def study_title(df: pd.DataFrame) -> str | None:
    """The study's title from the ``study_title`` column (whitespace collapsed), or None when the table has
    none. Titles of merged tables that differ are joined with " / "."""
    if "study_title" not in df.columns:
        return None
    titles = [" ".join(str(t).split()) for t in df["study_title"].dropna().unique()]
    titles = [t for t in dict.fromkeys(titles) if t]
    return " / ".join(titles) or None


def questionnaire_from_results(df: pd.DataFrame) -> pd.DataFrame | None:
    """The questionnaire answers the table carries (``questionnaire:<scale>:<item>`` columns), one row per
    participant and item (participant, item, scale, value, _where), as
    :func:`results_analysis.loader.load_questionnaire` reads them from a file; None when it carries none.
    An empty scale means none was stored: the item's own ``scale.item`` prefix, else ``questionnaire``.
    Raises :class:`AnalysisInputError` when one participant's rows disagree on an answer.
    """
    columns = [c for c in df.columns if isinstance(c, str) and c.startswith(QUESTIONNAIRE_PREFIX)]
    if not columns:
        return None
    where = df["_where"] if "_where" in df.columns else pd.Series([f"row {i + 1}" for i in range(len(df))],
                                                                   index=df.index)
    rows = []
    participants = df["participant"].astype(str)
    for col in columns:
        scale, _, item = col[len(QUESTIONNAIRE_PREFIX):].rpartition(":")
        answered = df[col].notna() & (df[col].astype(str).str.strip() != "")
        for participant, sub in df[answered].groupby(participants[answered], sort=False):
            values = sub[col].astype(str).str.strip()
            if values.nunique() > 1:
                first = values.iloc[0]
                other = int(np.argmax((values != first).to_numpy()))
                raise AnalysisInputError(df.attrs.get("source"),
                                         f"{where[sub.index[0]]} and {where[sub.index[other]]}, column '{col}'",
                                         f"participant {participant}'s rows give two answers ({first!r} and "
                                         f"{values.iloc[other]!r}) to one questionnaire item")
            rows.append({"participant": participant, "item": item, "scale": scale if scale.strip() else _scale_of(item),
                         "value": values.iloc[0],
                         "_where": f"{where[sub.index[0]]}, column '{col}'"})
    return pd.DataFrame(rows, columns=["participant", "item", "scale", "value", "_where"])


#: Dataclass fields that hold a single condition id (a lone string is otherwise never relabelled): the rank
#: analysis's ``control``, a rating block's hidden ``reference``.
_CONDITION_FIELDS = frozenset({"control", "reference"})


def relabel(obj: T, labels: Mapping[str, str]) -> T:
    """A copy of ``obj`` (an analysis, or any of its dataclasses, frames, lists and dicts) with every condition
    id replaced by its label, for display: frame columns whose values are all condition ids, frame columns
    of one family named ``<prefix>_<id>`` for every id, lists and arrays of ids, and dict keys that are all
    ids. Numbers are untouched; a string that merely contains an id is left as it is.
    """
    if all(k == v for k, v in labels.items()):
        return obj
    ids = set(labels)

    def all_ids(values) -> bool:
        values = list(values)
        return bool(values) and all(isinstance(v, str) and v in ids for v in values)

    def frame(df: pd.DataFrame) -> pd.DataFrame:
        out = df.copy()
        for col in out.columns:
            text = pd.api.types.is_object_dtype(out[col]) or pd.api.types.is_string_dtype(out[col])
            if text and all_ids(out[col].dropna()):
                out[col] = out[col].map(lambda v: labels.get(v, v))
        renames = {}
        for col in map(str, out.columns):
            for cid in ids:
                prefix = col[: -len(cid) - 1]
                if col.endswith(f"_{cid}") and all(f"{prefix}_{j}" in out.columns for j in ids):
                    renames[col] = f"{prefix}_{labels[cid]}"
        out = out.rename(columns=renames)
        if all_ids(out.index):
            out.index = [labels[v] for v in out.index]
        return out

    def walk(x):
        if isinstance(x, pd.DataFrame):
            return frame(x)
        if dataclasses.is_dataclass(x) and not isinstance(x, type):
            new = copy.copy(x)
            for f in dataclasses.fields(x):
                value = getattr(x, f.name)
                # a field that names one condition (the analysis's ``control``) is shown by its label too
                shown = labels[value] if f.name in _CONDITION_FIELDS and value in ids else walk(value)
                object.__setattr__(new, f.name, shown)
            return new
        if isinstance(x, dict):
            keys = all_ids(x)
            return {(labels[k] if keys else k): walk(v) for k, v in x.items()}
        if isinstance(x, (list, tuple)):
            return type(x)(labels[v] for v in x) if all_ids(x) else type(x)(walk(v) for v in x)
        if isinstance(x, np.ndarray) and x.dtype == object and x.ndim == 1 and all_ids(x):
            return np.array([labels[v] for v in x], dtype=object)
        return x

    return walk(obj)
