"""Export a results database as tidy tables (what ``results_analysis`` and R/SPSS users read).

The long table has one row per participant x trial x criterion x condition, columns :data:`CORE_COLUMNS`
in that order, then one column per stimulus tag (e.g. ``speaker``) and per participant group (e.g.
``device``, ``ordering_version``), then ``design_hash`` and ``app_version``. ``slot`` is 0 (left),
1 (middle), 2 (right); ``rank`` is 1 (best) to 3, average ranks for ties; ``attention_passed`` is empty for
trials that are not attention checks; ``trial_duration_s`` is how long the trial played (empty for trials
stored before studyapp recorded it); ``sample`` is the 1-based sample of the condition that slot showed (see
``samples`` in :class:`~studyapp.study.design.Condition`; 1 for a condition with one motion per stimulus,
empty for trials stored before studyapp recorded it). Practice trials are included and flagged (``is_practice``): the
analysis drops them, and they show whether participants understood the task.

Example
-------
>>> import tempfile, pathlib
>>> from studyapp.study.storage import ResultsDB
>>> p = pathlib.Path(tempfile.mkdtemp()) / "r.sqlite"
>>> ResultsDB(p, design_hash="ab12", title="t").close()
>>> list(export_dataframe(p).columns)[:4]
['participant', 'session', 'trial_index', 'stimulus']
"""
from __future__ import annotations

import json
from pathlib import Path

import pandas as pd

from studyapp.study.storage import ResultsDB

CORE_COLUMNS = (
    "participant", "session", "trial_index", "stimulus", "criterion", "condition", "slot", "rank", "plays",
    "response_time_s", "is_practice", "is_attention_check", "attention_passed", "trial_duration_s",
    "sample",
)
TAIL_COLUMNS = ("design_hash", "app_version")

# Criteria keep the design's order (the order a trial's answers are stored in, so the first stored row of
# each criterion tells it): the analysis tables and figures follow the row order, and a reader expects
# "realism, synchronization, diversity" as the participants saw them, not the alphabet.
_QUERY = """
WITH crit AS (SELECT criterion, MIN(rowid) AS pos FROM responses GROUP BY criterion)
SELECT r.participant, t.session, r.trial_index, t.stimulus, r.criterion, r.condition, r.slot, r.rank,
       t.plays, t.response_time_s, t.is_practice, t.is_attention_check, t.attention_passed, t.trial_duration_s,
       CASE r.slot WHEN 0 THEN t.sample_left WHEN 1 THEN t.sample_middle ELSE t.sample_right END AS sample,
       r.design_hash, r.app_version, c.position AS _cond_pos
FROM responses r
JOIN trials t ON t.participant = r.participant AND t.trial_index = r.trial_index
JOIN crit ON crit.criterion = r.criterion
LEFT JOIN conditions c ON c.id = r.condition
ORDER BY r.participant, r.trial_index, crit.pos, r.slot
"""


def _open(db: str | Path | ResultsDB) -> tuple[ResultsDB, bool]:
    if isinstance(db, ResultsDB):
        return db, False
    return ResultsDB(db, create=False), True


def export_dataframe(db: str | Path | ResultsDB, *, include_practice: bool = True) -> pd.DataFrame:
    """The tidy long table of a results database (path or open :class:`ResultsDB`)."""
    rdb, owned = _open(db)
    try:
        con = rdb.connection
        df = pd.read_sql_query(_QUERY, con)
        tags = rdb.stimulus_tags()
        groups = {p.id: p.groups for p in rdb.participants()}
    finally:
        if owned:
            rdb.close()
    df = df.drop(columns=["_cond_pos"])
    for col in ("is_practice", "is_attention_check"):
        df[col] = df[col].astype(bool)
    df["sample"] = df["sample"].astype("Int64")  # whole numbers, empty where not recorded
    df["attention_passed"] = df["attention_passed"].map(lambda v: None if pd.isna(v) else bool(v)).astype(object)
    if not include_practice:
        df = df[~df["is_practice"]].reset_index(drop=True)
    extra: list[str] = []
    for mapping, key in ((tags, "stimulus"), (groups, "participant")):
        names = sorted({k for d in mapping.values() for k in d})
        for name in names:
            if name in df.columns or name in extra:
                continue  # never shadow a core column (or a tag) with a group of the same name
            df[name] = df[key].map(lambda v, n=name: mapping.get(v, {}).get(n))
            extra.append(name)
    return df[list(CORE_COLUMNS) + extra + list(TAIL_COLUMNS)]


def questionnaire_dataframe(db: str | Path | ResultsDB) -> pd.DataFrame:
    """Questionnaire answers: participant, item, scale, kind, value (Likert points; empty for text items),
    text (the answer to text items), design_hash, app_version."""
    rdb, owned = _open(db)
    try:
        rows = rdb.questionnaire()
    finally:
        if owned:
            rdb.close()
    out = []
    for r in rows:
        likert = r.get("kind", "likert") != "text"
        out.append({
            "participant": r["participant"], "item": r["item"], "scale": r.get("scale") or "",
            "kind": r.get("kind") or "likert",
            "value": pd.to_numeric(r["value"], errors="coerce") if likert else None,
            "text": None if likert else r["value"],
            "design_hash": r["design_hash"], "app_version": r["app_version"],
        })
    cols = ["participant", "item", "scale", "kind", "value", "text", "design_hash", "app_version"]
    return pd.DataFrame(out, columns=cols)


def export_json(db: str | Path | ResultsDB) -> dict:
    """Every table of the database as plain JSON-able rows (the portable copy in a results file)."""
    rdb, owned = _open(db)
    try:
        con = rdb.connection
        out = {"schema": "studyapp-results", "design_hash": rdb.design_hash, "title": rdb.title}
        for table in ("study", "stimuli", "conditions", "participants", "sessions", "trials", "responses", "plays",
                      "questionnaire"):
            out[table] = [dict(r) for r in con.execute(f"SELECT * FROM {table}")]
    finally:
        if owned:
            rdb.close()
    return json.loads(json.dumps(out, default=str))
