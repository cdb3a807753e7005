"""Build the tidy results frame straight from a studyapp results database (schema versions 1 to 7).

Reads with pandas and any DB-API connection that speaks SQLite's SQL (no studyapp import): an
:class:`sqlite3.Connection`, or studyapp's PostgreSQL connection, which answers the same statements (``studyapp
export`` of a ``postgresql://`` database runs this query through it). Responses joined with their trials, stimulus tags
(JSON in ``stimuli.tags``) and participant groups (JSON in ``participants.groups``) spread into columns,
exactly the columns of ``studyapp export``.

The table carries what the report needs besides the ranks, so a CSV export and its database give the same
report: each condition's ``condition_label`` (the design's label, else the id: a database before version 4
has no labels) and ``condition_position`` (its place in the design, the order of the report's tables and
figures; empty for a pseudo-condition such as an attention check's frozen slot), each criterion's
``criterion_label`` (the design's label, e.g. "Synchronization with speech", in the design's language; the id
in a database before version 7, or one upgraded and not yet opened with its design), the ``study_title`` (the
report's title) and each participant's questionnaire answers, one column per rated (Likert) item named
``questionnaire:<scale>:<item>`` (see :data:`QUESTIONNAIRE_PREFIX`; the scale part is empty where none was
stored). Free-text, choice and number answers stay out of the table (``studyapp export --questionnaire-csv`` has them).
It reads what it is given: the loader proves the file intact first
(:mod:`results_analysis.integrity`), as ``studyapp`` does when it opens a database.

Response paradigms (schema 6): after the core columns come :data:`PARADIGM_COLUMNS`. Rank answers come from
table ``responses``, pairwise, mismatch and rating answers from ``judgements`` (one row per criterion x slot
either way). ``block`` and ``paradigm`` are the trial's (``"main"`` and ``"rank"`` in a database before
version 6); ``rank`` is empty on non-rank rows; ``rating`` (0..100) is set on rating rows only;
``preference`` (-2..2, the preference FOR that row's slot: +2 clearly this one) on pairwise and mismatch rows
only; ``matched`` on mismatch rows only (1 for the slot playing its own speech's motion, 0 for the
mismatched one); ``motion_stimulus`` is the stimulus whose motion the slot played (the trial's stimulus
before version 6); ``reasons`` the JSON list of reasons chosen (pairwise), empty elsewhere. A mismatch row's
``condition`` is the condition shown in both slots.
"""
from __future__ import annotations

import json
import sqlite3
from pathlib import Path

import pandas as pd

from results_analysis.errors import AnalysisInputError

_NEEDED = {"responses": {"participant", "trial_index", "criterion", "condition", "rank"},
           "trials": {"participant", "trial_index", "stimulus"}}

#: The tidy table's first columns, in order; one column per stimulus tag and per participant group follows
#: (sorted, a name never shadowing an earlier column), then :data:`TAIL_COLUMNS`.
CORE_COLUMNS = (
    "participant", "session", "trial_index", "stimulus", "criterion", "criterion_label", "condition",
    "condition_label", "condition_position", "slot", "rank", "plays", "response_time_s", "is_practice",
    "is_attention_check", "attention_passed", "trial_duration_s", "sample",
)
#: The response-paradigm columns (schema 6), right after :data:`CORE_COLUMNS` (see the module notes).
PARADIGM_COLUMNS = ("block", "paradigm", "rating", "preference", "matched", "motion_stimulus", "reasons")
TAIL_COLUMNS = ("study_title", "design_hash", "app_version")
#: Name prefix of the questionnaire columns: ``questionnaire:<scale>:<item>`` (an item id holds no ``:``, so
#: the last ``:`` ends the scale). They follow the tag and group columns.
QUESTIONNAIRE_PREFIX = "questionnaire:"

# Criteria in the order the study asked them (answers are stored in that order, so the first stored row of
# each criterion tells it): the analysis tables and figures follow the row order, and a reader expects
# "realism, synchronization, diversity" as the participants saw them, not the alphabet.
_QUERY = """
WITH crit AS (SELECT criterion, MIN(rowid) AS pos FROM responses GROUP BY criterion)
SELECT r.rowid AS _rowid, r.participant, t.session, r.trial_index, t.stimulus, r.criterion, r.condition,
       r.slot, r.rank, t.plays, t.response_time_s, t.is_practice, t.is_attention_check, t.attention_passed,
       {trial_duration} AS trial_duration_s, {sample} AS sample, r.design_hash, r.app_version,
       {block} AS block, {paradigm} AS paradigm, {motion} AS motion_stimulus, crit.pos AS _crit
FROM responses r JOIN trials t ON t.participant = r.participant AND t.trial_index = r.trial_index
JOIN crit ON crit.criterion = r.criterion
{slots_join}
"""
# The answers of the other paradigms (schema 6), the same columns plus the judgement's value and reasons.
_JUDGEMENTS = """
WITH crit AS (SELECT criterion, MIN(rowid) AS pos FROM judgements GROUP BY criterion)
SELECT j.rowid AS _rowid, j.participant, t.session, j.trial_index, t.stimulus, j.criterion, j.condition,
       j.slot, NULL AS rank, t.plays, t.response_time_s, t.is_practice, t.is_attention_check, t.attention_passed,
       t.trial_duration_s, s.sample AS sample, j.design_hash, j.app_version,
       COALESCE(t.block, 'main') AS block, COALESCE(t.paradigm, 'rank') AS paradigm,
       COALESCE(s.motion_stimulus, t.stimulus) AS motion_stimulus, crit.pos AS _crit, j.value AS _value,
       j.reasons AS reasons
FROM judgements j JOIN trials t ON t.participant = j.participant AND t.trial_index = j.trial_index
JOIN crit ON crit.criterion = j.criterion
LEFT JOIN trial_slots s ON s.participant = j.participant AND s.trial_index = j.trial_index AND s.slot = j.slot
"""


def tidy_table(con: sqlite3.Connection, path: str | Path, *, include_practice: bool = True,
               rowid: bool = False) -> pd.DataFrame:
    """The tidy table of a results database, exactly as ``studyapp export`` writes it: one row per
    participant x trial x criterion x slot (x condition for rank), :data:`CORE_COLUMNS`,
    :data:`PARADIGM_COLUMNS`, the tag and group columns, then :data:`TAIL_COLUMNS`. ``attention_passed`` is
    empty (None) for trials that are not attention checks.

    This is the one place the query lives: ``studyapp export`` and :func:`tidy_from_connection` both call it.
    ``rowid``: keep each answer's row id in the database as a first column ``_rowid``, and its table
    (``responses`` or ``judgements``) as ``_table`` (for messages).
    """
    tables = {r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type IN ('table','view')")}
    for table, cols in _NEEDED.items():
        if table not in tables:
            raise AnalysisInputError(path, f"table {table}", "missing: not a studyapp results database")
        have = {r[1] for r in con.execute(f"PRAGMA table_info({table})")}
        if cols - have:
            raise AnalysisInputError(path, f"table {table}", f"missing column(s) {', '.join(sorted(cols - have))}")
    # Version 2 records how long each trial played; a version 1 file (read as it is, never upgraded here)
    # has no such column, and the table gets it empty.
    trial_cols = {r[1] for r in con.execute("PRAGMA table_info(trials)")}
    duration = "t.trial_duration_s" if "trial_duration_s" in trial_cols else "NULL"
    # Version 3 records the sample each slot showed (a condition with several motions per stimulus); older
    # files get it empty, as for trial_duration_s.
    sample = ("CASE r.slot WHEN 0 THEN t.sample_left WHEN 1 THEN t.sample_middle ELSE t.sample_right END"
              if {"sample_left", "sample_middle", "sample_right"} <= trial_cols else "NULL")
    # Version 6 records each trial's block and paradigm and every slot's motion; older files are one rank block.
    v6 = {"block", "paradigm"} <= trial_cols and "trial_slots" in tables
    df = _frame(con, _QUERY.format(
        trial_duration=duration, sample=sample,
        block="COALESCE(t.block, 'main')" if v6 else "'main'",
        paradigm="COALESCE(t.paradigm, 'rank')" if v6 else "'rank'",
        motion="COALESCE(s.motion_stimulus, t.stimulus)" if v6 else "t.stimulus",
        slots_join=("LEFT JOIN trial_slots s ON s.participant = r.participant AND s.trial_index = r.trial_index "
                    "AND s.slot = r.slot") if v6 else ""))
    df["_table"] = "responses"
    df["reasons"] = ""
    if v6 and "judgements" in tables:
        judged = _frame(con, _JUDGEMENTS)
        if len(judged):
            judged["_table"] = "judgements"
            df = pd.concat([df, judged], ignore_index=True) if len(df) else judged
    df = df.sort_values(["participant", "trial_index", "_crit", "slot"], kind="stable").reset_index(drop=True)
    value = df.pop("_value") if "_value" in df.columns else pd.Series(float("nan"), index=df.index)
    df["rank"] = df["rank"].astype(float)
    df["rating"] = value.where(df["paradigm"] == "rating").astype(float)
    df["preference"] = value.where(df["paradigm"].isin(["pairwise", "mismatch"])).astype(float)
    df["matched"] = pd.array([(1 if m == s else 0) if p == "mismatch" else None
                              for p, m, s in zip(df["paradigm"], df["motion_stimulus"], df["stimulus"])],
                             dtype="Int64")
    df["reasons"] = df["reasons"].fillna("").map(lambda r: "" if r in ("", "[]") else r).astype(object)
    for col in ("is_practice", "is_attention_check"):
        df[col] = df[col].astype(int).astype(bool)
    df["attention_passed"] = df["attention_passed"].map(lambda v: None if pd.isna(v) else bool(v)).astype(object)
    df["sample"] = df["sample"].astype("Int64")  # whole numbers, empty where not recorded
    extra: list[str] = []
    for table, query, key in (("stimuli", "SELECT id, tags FROM stimuli", "stimulus"),
                              ("participants", "SELECT id, groups FROM participants", "participant")):
        if table not in tables:
            continue
        mapping = _json_columns(con, query, path, f"{table}.{query.split()[2]}")
        for name in sorted({k for d in mapping.values() for k in d}):
            if name in df.columns or name in extra:
                continue  # never shadow a core column (or a tag) with a group of the same name
            df[name] = df[key].map(lambda v, n=name: mapping.get(str(v), {}).get(n))
            extra.append(name)
    labels, positions = _conditions(con, tables)
    df["condition_label"] = [labels.get(c) or c for c in df["condition"]]
    df["condition_position"] = pd.array([positions.get(c) for c in df["condition"]], dtype="Int64")
    criterion_names = _criterion_labels(con, tables)
    df["criterion_label"] = [criterion_names.get(c) or c for c in df["criterion"]]
    df["study_title"] = study_title_from_connection(con)
    answers = _questionnaire_columns(con, tables)
    for name, values in answers.items():
        if name not in df.columns and name not in extra:
            df[name] = df["participant"].map(lambda p, v=values: v.get(str(p)))
            extra.append(name)
    df = df[(["_rowid", "_table"] if rowid else []) + list(CORE_COLUMNS) + list(PARADIGM_COLUMNS) + extra
            + list(TAIL_COLUMNS)]
    if not include_practice:
        df = df[~df["is_practice"]].reset_index(drop=True)
    return df


def _frame(con: sqlite3.Connection, sql: str) -> pd.DataFrame:
    """A query's rows as a frame, as :func:`pandas.read_sql_query` makes it, from any DB-API connection
    (pandas reads only sqlite3 and SQLAlchemy connections itself)."""
    cur = con.execute(sql)
    columns = [d[0] for d in cur.description]
    return pd.DataFrame.from_records([tuple(r) for r in cur.fetchall()], columns=columns, coerce_float=True)


def tidy_from_connection(con: sqlite3.Connection, path: str | Path) -> pd.DataFrame:
    """The tidy frame the analysis reads: :func:`tidy_table`, each row's place in the database in ``_where``
    (for messages), and ``attention_passed`` true where there was nothing to fail."""
    df = tidy_table(con, path, rowid=True)
    df["_where"] = [f"{tb} row {r} (participant {p}, trial {t}, criterion {c})"
                    for r, tb, p, t, c in zip(df.pop("_rowid"), df.pop("_table"), df["participant"], df["trial_index"],
                                              df["criterion"])]
    # A trial that is not an attention check has attention_passed NULL: nothing to fail.
    df["attention_passed"] = df["attention_passed"].map(lambda v: True if v is None else bool(v)).astype(bool)
    return df


def study_title_from_connection(con: sqlite3.Connection) -> str | None:
    """The study title stored in table ``study`` (column ``title``), whitespace collapsed to single spaces; None
    when the database has no such table or column or the title is empty (studyapp stores '' for an untitled
    design), so the caller can fall back to something else."""
    tables = {r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type IN ('table','view')")}
    if "study" not in tables or "title" not in {r[1] for r in con.execute("PRAGMA table_info(study)")}:
        return None
    row = con.execute("SELECT title FROM study ORDER BY rowid LIMIT 1").fetchone()
    # A heading is one line: a newline in the stored title would otherwise break the Markdown report.
    title = " ".join(str(row[0]).split()) if row and row[0] is not None else ""
    return title or None


def questionnaire_from_connection(con: sqlite3.Connection, path: str | Path) -> pd.DataFrame:
    """Questionnaire answers (participant, item, scale, kind, value). The scale is the stored ``scale`` column
    when the database has one; otherwise (or when it is empty) an item named ``scale.item`` or
    ``scale:item`` belongs to ``scale`` and any other item to the scale ``questionnaire``."""
    have = {r[1] for r in con.execute("PRAGMA table_info(questionnaire)")}
    extra = ", ".join(c for c in ("scale", "kind") if c in have)
    rows = pd.read_sql_query(f"SELECT rowid AS _rowid, participant, item, value{', ' + extra if extra else ''} "
                             "FROM questionnaire", con)
    rows["_where"] = [f"questionnaire row {r}" for r in rows.pop("_rowid")]
    stored = rows["scale"] if "scale" in rows.columns else pd.Series([None] * len(rows), dtype=object)
    rows["scale"] = [s if isinstance(s, str) and s.strip() else _scale_of(i) for s, i in zip(stored, rows["item"])]
    return rows


def _conditions(con: sqlite3.Connection, tables: set[str]) -> tuple[dict[str, str | None], dict[str, int]]:
    """Each condition's stored label (None before schema version 4, or none given) and design position."""
    if "conditions" not in tables:
        return {}, {}
    have = {r[1] for r in con.execute("PRAGMA table_info(conditions)")}
    label = "label" if "label" in have else "NULL"
    position = "position" if "position" in have else "NULL"
    rows = con.execute(f"SELECT id, {label}, {position} FROM conditions").fetchall()
    return ({str(i): (str(lb) if lb is not None and str(lb).strip() else None) for i, lb, _ in rows},
            {str(i): int(p) for i, _, p in rows if p is not None})


def _criterion_labels(con: sqlite3.Connection, tables: set[str]) -> dict[str, str]:
    """Each criterion's stored label (none before schema version 7, or before the design was recorded)."""
    if "criteria" not in tables or "label" not in {r[1] for r in con.execute("PRAGMA table_info(criteria)")}:
        return {}
    return {str(i): " ".join(str(lb).split()) for i, lb in con.execute("SELECT id, label FROM criteria")
            if lb is not None and str(lb).strip()}


def _questionnaire_columns(con: sqlite3.Connection, tables: set[str]) -> dict[str, dict[str, str | None]]:
    """``{column name: {participant: stored answer}}`` of the rated items, in the order first answered."""
    if "questionnaire" not in tables:
        return {}
    have = {r[1] for r in con.execute("PRAGMA table_info(questionnaire)")}
    scale = "scale" if "scale" in have else "NULL"
    kind = "kind" if "kind" in have else "NULL"
    out: dict[str, dict[str, str | None]] = {}
    for participant, item, sc, kd, value in con.execute(
            f"SELECT participant, item, {scale}, {kind}, value FROM questionnaire ORDER BY rowid"):
        # only Likert answers are numbers on a scale: a number item (age) or a choice would otherwise be
        # summarised and put into a scale's Cronbach alpha with the Likert items
        if str(kd or "likert").lower() != "likert":
            continue
        name = f"{QUESTIONNAIRE_PREFIX}{sc if isinstance(sc, str) and sc.strip() else ''}:{item}"
        out.setdefault(name, {})[str(participant)] = None if value is None else str(value)
    return out


def _scale_of(item: str) -> str:
    for sep in (".", ":"):
        if sep in item:
            return item.split(sep, 1)[0]
    return "questionnaire"


def _json_columns(con: sqlite3.Connection, query: str, path, where: str) -> dict[str, dict[str, str]]:
    out = {}
    for key, text in con.execute(query):
        try:
            value = json.loads(text or "{}")
        except json.JSONDecodeError as exc:
            raise AnalysisInputError(path, f"{where} of {key}", f"not valid JSON ({exc})") from exc
        out[str(key)] = {str(k): str(v) for k, v in (value or {}).items()}
    return out
