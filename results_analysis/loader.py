"""Load exported study results into one tidy DataFrame, from the CSV export or the SQLite database.

The tidy frame has one row per participant x trial x criterion x condition (the columns of
``studyapp export``). Whatever the source, the frame comes back with the same columns and dtypes, the
source path in ``df.attrs["source"]`` and, in ``_where``, where each row came from (``line 12`` of a
CSV, ``responses id 5`` of a database) so validation errors can point at it.
"""
from __future__ import annotations

import sqlite3
from collections import defaultdict
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

import numpy as np
import pandas as pd

from results_analysis.errors import AnalysisInputError, unreadable_csv
from results_analysis.where_labels import PlaceArray

#: Columns every results table must have.
REQUIRED_COLUMNS = ("participant", "trial_index", "stimulus", "criterion", "condition", "rank")
#: Boolean flags of the export; missing ones default to False (attention_passed to True).
FLAG_COLUMNS = ("is_practice", "is_attention_check", "attention_passed")
#: Columns that are bookkeeping, never a stimulus tag or participant group.
CORE_COLUMNS = REQUIRED_COLUMNS + FLAG_COLUMNS + (
    "session", "slot", "plays", "response_time_s", "trial_duration_s", "sample", "design_hash", "app_version", "_where",
    "condition_label", "condition_position", "study_title", "criterion_label",
    "block", "paradigm", "rating", "preference", "matched", "motion_stimulus", "reasons")
#: The response-paradigm columns and their value in a table without them (an export before schema 6 is one
#: rank block "main"); see :mod:`results_analysis.sqlite_schema`.
PARADIGM_DEFAULTS = {"block": "main", "paradigm": "rank", "rating": np.nan, "preference": np.nan,
                     "matched": np.nan, "motion_stimulus": None, "reasons": ""}

#: Columns the loader adds for its own use (``_where``: where a row came from, for messages); never shown
#: to users as one of their columns.
INTERNAL_COLUMNS = ("_where",)

#: Columns :func:`normalize_results` makes text (object: str or None) and numbers (float).
_TEXT_COLUMNS = ("participant", "stimulus", "criterion", "condition", "session", "design_hash", "app_version",
                 "condition_label", "criterion_label", "study_title", "block", "paradigm", "motion_stimulus", "reasons")
_NUMBER_COLUMNS = ("rank", "trial_index", "slot", "plays", "response_time_s", "trial_duration_s", "sample",
                   "condition_position", "rating", "preference", "matched")

_TRUE = {"1", "true", "t", "yes", "y"}
_FALSE = {"0", "false", "f", "no", "n", ""}


def _is_sqlite(path: Path) -> bool:
    """True for a SQLite database (by its header, whatever the file is called); the file must exist."""
    if not path.exists():
        if str(path).startswith(("postgresql:", "postgres:")):    # a `studyapp serve --db` URL (Path ate its //)
            raise AnalysisInputError(path, None, "a PostgreSQL database is not read here: write it out with "
                                     "`studyapp export URL --csv results.csv` and analyse the CSV")
        raise AnalysisInputError(path, None, "file not found")
    with open(path, "rb") as fh:
        return fh.read(16).startswith(b"SQLite format 3")


def load_results(path: str | Path) -> pd.DataFrame:
    """Read results from a tidy CSV (``studyapp export --csv``) or a results SQLite database.

    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "r.csv"
    >>> _ = p.write_text("participant,trial_index,stimulus,criterion,condition,rank\\n"
    ...                  "P1,0,clip1,realism,A,1\\nP1,0,clip1,realism,B,2\\n")
    >>> df = load_results(p)
    >>> df[["participant", "condition", "rank"]].values.tolist()
    [['P1', 'A', 1.0], ['P1', 'B', 2.0]]
    """
    path = Path(path)
    if _is_sqlite(path):
        df = _read_sqlite(path)
    else:
        df = _read_numbers_csv(path)
        if df is None:
            df = _read_text_csv(path)
        # Line numbers as a text editor shows them: the header is line 1. Kept as numbers, read as text: a
        # million strings take a fifth of a second to write, and only an error message reads one.
        df["_where"] = pd.Series(PlaceArray.lines(len(df)), index=df.index, copy=False)
    return normalize_results(df, source=path)


def _csv_dtypes(numbers) -> defaultdict:
    """read_csv's dtypes: the columns normalize_results converts as object (pandas' str dtype is slower per
    operation and would become object text or numbers anyway), the number columns as ``numbers``, any other
    column (a stimulus tag, a participant group) as pandas' str."""
    return defaultdict(lambda: str, {**{c: object for c in _TEXT_COLUMNS + FLAG_COLUMNS},
                                     **{c: numbers for c in _NUMBER_COLUMNS}})


def _read_numbers_csv(path: Path) -> pd.DataFrame | None:
    """The CSV with its number columns parsed to floats by pandas' C parser, or None where that could differ
    from :func:`_read_text_csv` + :func:`normalize_results`.

    A large export has millions of number cells: as text each becomes a Python string, then a parsed
    distinct value; parsed in C (without the GIL, on pandas' reader threads) none does. The two agree on
    every cell C parses (the same decimal-to-float conversion; checked against ``pandas.to_numeric`` cell by
    cell in the tests), with one exception: C keeps the sign of ``-0``, which ``to_numeric`` reads as the
    integer 0. A file with a cell C cannot read as a number (``x``, ``nan``; a damaged file) or with a
    negative zero gives None: the text read then names the cell, or reads it as before.
    """
    try:
        df = pd.read_csv(path, dtype=_csv_dtypes(np.float64), keep_default_na=False, na_values=[""])
    except (ValueError, OverflowError):  # ParserError and UnicodeDecodeError too: the text read reports them
        return None
    for col in _NUMBER_COLUMNS:
        if col in df.columns:
            values = df[col].to_numpy()
            if np.signbit(values[values == 0]).any():
                return None
    return df


def _read_text_csv(path: Path) -> pd.DataFrame:
    """The CSV with every cell of the columns :func:`normalize_results` converts as the text written."""
    try:
        return pd.read_csv(path, dtype=_csv_dtypes(object), keep_default_na=False, na_values=[""])
    except (pd.errors.ParserError, UnicodeDecodeError) as exc:
        raise unreadable_csv(path, exc) from exc


def normalize_results(df: pd.DataFrame, source: str | Path | None = None) -> pd.DataFrame:
    """Give a results frame (e.g. from ``studyapp.study.export.export_dataframe``) the canonical dtypes.

    Identifiers become strings, ``rank`` and ``trial_index`` numbers, flags booleans. Raises
    :class:`AnalysisInputError` naming the column and row when a value cannot be read.
    """
    src = str(source) if source is not None else df.attrs.get("source")
    df = df.copy(deep=False)  # copy-on-write: the caller's frame is never changed, and no column is copied
    if "_where" not in df.columns:
        df["_where"] = pd.Series([f"row {i + 1}" for i in range(len(df))], index=df.index, dtype=object)
    missing = [c for c in REQUIRED_COLUMNS if c not in df.columns]
    if missing:
        found = [str(c) for c in df.columns if c not in INTERNAL_COLUMNS]
        raise AnalysisInputError(src, f"column(s) {', '.join(missing)}",
                                 f"missing required column(s); found: {', '.join(found) or 'no columns'}")
    whole = set()  # text columns without a gap: no isna (slow on object columns) needed
    for col in _TEXT_COLUMNS:
        if col in df.columns:
            if df[col].dtype == object and _all_text(df[col]):  # e.g. normalized before: kept as it is
                whole.add(col)
                continue
            df[col] = _as_text(df[col])
    for col in ("participant", "stimulus", "criterion", "condition"):
        if col in whole:
            continue
        bad = df[col].isna()
        if bad.any():
            raise AnalysisInputError(src, f"{df['_where'].iloc[int(np.argmax(bad.to_numpy()))]}, column '{col}'",
                                     "empty value")
    for col, default in PARADIGM_DEFAULTS.items():
        if col not in df.columns:
            if isinstance(default, str):  # text as object, like every text column here (pandas' str dtype
                # would be converted again by the next normalize_results, as the analysis calls it)
                df[col] = pd.Series(_constant_text(len(df), default), index=df.index, dtype=object, copy=False)
                whole.add(col)
            elif col == "motion_stimulus":  # each row's own stimulus (the fill below), sharing its column
                df[col] = df["stimulus"]
                whole.add(col)
            else:
                df[col] = default
    # a column known to be whole text has nothing to fill (each fillna of a million-cell object column scans it)
    for col, fill in (("block", "main"), ("paradigm", "rank"), ("reasons", "")):
        if col not in whole:
            df[col] = df[col].fillna(fill)
    if "motion_stimulus" not in whole:
        df["motion_stimulus"] = df["motion_stimulus"].where(df["motion_stimulus"].notna(), df["stimulus"])
    for col in _NUMBER_COLUMNS:
        if col in df.columns:
            num, missing = _number_column(df[col])
            gap = np.isnan(num.to_numpy())
            bad = gap & ~missing
            if col == "trial_index":
                bad |= gap
            elif col == "rank" and gap.any():  # a rank row needs its rank; other paradigms' rows have none
                bad |= gap & (df["paradigm"] == "rank").to_numpy()
            if bad.any():
                i = int(np.argmax(bad))
                raise AnalysisInputError(src, f"{df['_where'].iloc[i]}, column '{col}'",
                                         f"{df[col].iloc[i]!r} is not a number")
            df[col] = num.astype(float)
    for col in FLAG_COLUMNS:
        default = col == "attention_passed"
        if col not in df.columns:
            df[col] = default
            continue
        df[col] = _parse_flags(df[col], col, df["_where"], src, default)
    df.attrs["source"] = src
    return df.reset_index(drop=True)


def load_questionnaire(path: str | Path) -> pd.DataFrame:
    """Read questionnaire answers: a CSV with participant, item, scale, value (or the results database).

    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "q.csv"
    >>> _ = p.write_text("participant,item,scale,value\\nP1,q1,ease,4\\nP1,q2,ease,5\\n")
    >>> load_questionnaire(p)["value"].tolist()
    [4.0, 5.0]
    """
    path = Path(path)
    if _is_sqlite(path):
        from results_analysis.sqlite_schema import questionnaire_from_connection

        try:
            with _open_verified(path) as con:
                if "questionnaire" not in _tables(con):
                    raise AnalysisInputError(path, "table questionnaire", "missing")
                q = questionnaire_from_connection(con, path)
        except (sqlite3.DatabaseError, pd.errors.DatabaseError, UnicodeDecodeError) as exc:
            raise AnalysisInputError(path, "table questionnaire", f"not readable ({exc})") from exc
    else:
        q = pd.read_csv(path, dtype=str, keep_default_na=False, na_values=[""])
        q["_where"] = [f"line {i + 2}" for i in range(len(q))]
    return normalize_questionnaire(q, path)


def normalize_questionnaire(q: pd.DataFrame, path: str | Path | None) -> pd.DataFrame:
    """Questionnaire answers as the analysis reads them (see :func:`load_questionnaire`): rated items only,
    ``scale`` filled in, ``value`` a number, unanswered items dropped; ``path`` names the source in errors."""
    if "kind" in q.columns:
        # Only rated (Likert) items are summarised as numbers: text, choice and number items (e.g. age) are
        # descriptive answers, not points on a scale.
        q = q[q["kind"].fillna("likert").astype(str).str.lower() == "likert"].copy()
    missing = [c for c in ("participant", "item", "value") if c not in q.columns]
    if missing:
        raise AnalysisInputError(path, f"column(s) {', '.join(missing)}", "missing required column(s)")
    if "scale" not in q.columns:
        q["scale"] = "questionnaire"
    q["scale"] = q["scale"].fillna("questionnaire").replace("", "questionnaire")
    for col in ("participant", "item", "scale"):
        q[col] = q[col].astype(str)
    num = pd.to_numeric(q["value"], errors="coerce")
    bad = num.isna() & q["value"].notna()
    if bad.any():
        i = int(np.argmax(bad.to_numpy()))
        raise AnalysisInputError(path, f"{q['_where'].iloc[i]}, column 'value'", f"{q['value'].iloc[i]!r} is not a number")
    q["value"] = num.astype(float)
    q = q[q["value"].notna()].copy()  # unanswered items
    dup = q.duplicated(["participant", "item"], keep=False)
    if dup.any():
        rows = q.loc[dup, "_where"].tolist()[:2]
        raise AnalysisInputError(path, " and ".join(rows), "the same participant answered the same item twice")
    q.attrs["source"] = str(path) if path is not None else None
    return q.reset_index(drop=True)


def load_study_title(path: str | Path) -> str | None:
    """The study title a results database stores, or a CSV export carries (column ``study_title``), or None.

    >>> import tempfile, pathlib, sqlite3
    >>> db = pathlib.Path(tempfile.mkdtemp()) / "s.sqlite"
    >>> with sqlite3.connect(db) as con:
    ...     _ = con.execute("CREATE TABLE study (id INTEGER PRIMARY KEY, title TEXT)")
    ...     _ = con.execute("INSERT INTO study VALUES (1, 'Gesture realism')")
    >>> load_study_title(db)
    'Gesture realism'
    """
    path = Path(path)
    if not _is_sqlite(path):
        from results_analysis.study_meta import study_title

        try:
            head = pd.read_csv(path, dtype=str, usecols=lambda c: c == "study_title", keep_default_na=False,
                               na_values=[""])
        except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
            raise unreadable_csv(path, exc) from exc
        return study_title(head)
    from results_analysis.sqlite_schema import study_title_from_connection

    try:
        with _open_verified(path) as con:
            return study_title_from_connection(con)
    except (sqlite3.DatabaseError, pd.errors.DatabaseError, UnicodeDecodeError) as exc:
        raise AnalysisInputError(path, "table study", f"not readable ({exc})") from exc


# --- SQLite -------------------------------------------------------------------------------------------


@contextmanager
def _open_verified(path: Path) -> Iterator[sqlite3.Connection]:
    """A read-only connection to a results database whose every row matched its checksum
    (:func:`results_analysis.integrity.verify_database`): a damaged file is reported, never analysed."""
    from results_analysis.integrity import verify_database

    con = sqlite3.connect(f"file:{path}?mode=ro", uri=True, isolation_level=None)
    try:
        con.execute("BEGIN")  # one snapshot: what was verified is what is read
        verify_database(con, path)
        yield con
    finally:
        con.close()


def _tables(con: sqlite3.Connection) -> set[str]:
    return {r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type IN ('table','view')")}


def _read_sqlite(path: Path) -> pd.DataFrame:
    from results_analysis.sqlite_schema import tidy_from_connection

    try:
        with _open_verified(path) as con:
            return tidy_from_connection(con, path)
    except (sqlite3.DatabaseError, pd.errors.DatabaseError, UnicodeDecodeError) as exc:
        raise AnalysisInputError(path, None, f"not a readable SQLite results database ({exc})") from exc


# --- helpers ------------------------------------------------------------------------------------------


def _isna(v) -> bool:
    return v is None or (isinstance(v, float) and np.isnan(v)) or v is pd.NA


def _as_text(col: pd.Series) -> pd.Series:
    """Each value as ``str(v)``, missing values as None (object dtype).

    A large study has millions of cells, so the common cases are done column-wise: text columns (a CSV read
    as strings) only get their missing values replaced, plain numeric columns are converted by numpy. A mixed
    object column keeps the cell-by-cell rule, where ``str`` of each value decides (``1`` and ``1.0`` differ).
    """
    values = col.to_numpy(dtype=object)
    if pd.api.types.infer_dtype(values, skipna=True) in ("string", "empty"):  # object or pandas' str dtype
        out = values.copy()
        out[pd.isna(values)] = None
        return pd.Series(out, index=col.index, dtype=object, copy=False)
    if col.dtype.kind in "iub":  # no missing values possible; numpy's str of an integer is Python's
        return pd.Series(col.astype(str).to_numpy(dtype=object), index=col.index, dtype=object, copy=False)
    return col.map(lambda v: None if _isna(v) else str(v)).astype(object)


def _constant_text(n: int, value: str) -> np.ndarray:
    """``np.full(n, value, dtype=object)``, which takes 20 times as long for an object array (50 ms for a
    million cells)."""
    out = np.empty(n, dtype=object)
    out[:] = value
    return out


def _all_text(col: pd.Series) -> bool:
    """Every value is a ``str`` (none missing), by one C pass over the column."""
    return len(col) > 0 and pd.api.types.infer_dtype(col.to_numpy(dtype=object), skipna=False) == "string"


def _to_number(col: pd.Series) -> pd.Series:
    """``pd.to_numeric(col, errors="coerce")`` as floats. A text column of a large study holds few distinct
    values (ranks, trial numbers, slots) in millions of cells: each distinct text is parsed once."""
    return _number_column(col)[0]


def _number_column(col: pd.Series) -> tuple[pd.Series, np.ndarray]:
    """:func:`_to_number` and where ``col`` is missing (``col.isna()``, read from the same factorization:
    isna of a million-cell object column costs as much again)."""
    if col.dtype == np.float64:  # e.g. parsed by read_csv: to_numeric would only copy it
        return col, np.isnan(col.to_numpy())
    if col.dtype.kind in "iufb":
        return pd.to_numeric(col, errors="coerce").astype(float), col.isna().to_numpy()
    codes, uniques = pd.factorize(col.to_numpy(dtype=object), use_na_sentinel=True)
    parsed = pd.to_numeric(pd.Series(uniques, dtype=object), errors="coerce").to_numpy(dtype=float)
    out = np.append(parsed, np.nan)[codes]  # code -1 (missing) picks the appended NaN
    return pd.Series(out, index=col.index, copy=False), codes < 0


def _flag_value(v, default: bool) -> bool | None:
    """One flag cell as a bool, None when it is not a true/false flag."""
    if isinstance(v, (bool, np.bool_)):
        return bool(v)
    s = str(v).strip().lower()
    if s.endswith(".0"):
        s = s[:-2]
    if s in _TRUE:
        return True
    if s in _FALSE:
        return False if s else default
    return None


def _parse_flags(col: pd.Series, name: str, where: pd.Series, src, default: bool) -> pd.Series:
    if col.dtype == bool:
        return col
    values = col.to_numpy(dtype=object)
    true = values == "True"
    if (true | (values == "False")).all():  # as pandas writes flags: two comparisons in C, no hashing
        return pd.Series(true, index=col.index, copy=False)
    # A flag column holds a handful of distinct values: read each once, not once per cell. Values equal in
    # Python (1, 1.0, True) share one entry and read the same; uniques come in order of first appearance, so
    # the first unreadable one is also the first bad row.
    codes, uniques = pd.factorize(values, use_na_sentinel=True)
    parsed = [_flag_value(v, default) for v in uniques]
    for j, flag in enumerate(parsed):
        if flag is None:
            i = int(np.argmax(codes == j))
            raise AnalysisInputError(src, f"{where.iloc[i]}, column '{name}'",
                                     f"{uniques[j]!r} is not a true/false flag")
    table = np.array(parsed + [default], dtype=bool)  # code -1 (missing) picks the last entry: the default
    return pd.Series(table[codes], index=col.index, copy=False)
