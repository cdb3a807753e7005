"""Export a results database as tidy tables (what ``results_analysis`` and R/SPSS users read).

The long table has one row per participant x trial x criterion x slot (x condition for rank), columns
:data:`CORE_COLUMNS` in that order, then one column per stimulus tag (e.g. ``speaker``) and per participant group (e.g.
``device``, ``ordering_version``), one per rated questionnaire item (``questionnaire:<scale>:<item>``, the
participant's answer), then ``study_title``, ``design_hash`` and ``app_version``. ``condition_label`` is the
design's label of the condition (its id when it has none) and ``condition_position`` its place in the design
(see :mod:`results_analysis.sqlite_schema`): with the title and the questionnaire they make a CSV give the
same report as its database. ``slot`` is 0 (left),
1 (middle), 2 (right); ``rank`` is 1 (best) to 3, average ranks for ties; ``attention_passed`` is empty for
trials that are not attention checks; ``trial_duration_s`` is how long the trial played (empty for trials
stored before studyapp recorded it); ``sample`` is the 1-based sample of the condition that slot showed (see
``samples`` in :class:`~studyapp.study.design.Condition`; 1 for a condition with one motion per stimulus,
empty for trials stored before studyapp recorded it). Practice trials are included and flagged (``is_practice``): the
analysis drops them, and they show whether participants understood the task. After the core columns come the
response-paradigm columns (``block``, ``paradigm``, ``rating``, ``preference``, ``matched``,
``motion_stimulus``, ``reasons``; see :mod:`results_analysis.sqlite_schema`): pairwise, mismatch and rating
answers are rows of their own, one per criterion x slot, with ``rank`` empty.

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

from results_analysis import sqlite_schema
from studyapp.study.storage import ResultsDB

# The tidy table has one owner, results_analysis (which reads databases itself): export calls its query.
CORE_COLUMNS = sqlite_schema.CORE_COLUMNS
TAIL_COLUMNS = sqlite_schema.TAIL_COLUMNS


def _open(db: str | Path | ResultsDB) -> tuple[ResultsDB, bool]:
    if isinstance(db, ResultsDB):
        return db, False
    return ResultsDB(db, create=False), True


def export_dataframe(db: str | Path | ResultsDB, *, include_practice: bool = True) -> pd.DataFrame:
    """The tidy long table of a results database (path or open :class:`ResultsDB`)."""
    rdb, owned = _open(db)
    try:
        df = sqlite_schema.tidy_table(rdb.connection, rdb.path, include_practice=include_practice)
    finally:
        if owned:
            rdb.close()
    return df


def record_design(db: str | Path | ResultsDB, design: str | Path) -> None:
    """Record in the database the labels its export shows, from ``design``: the criteria's labels and questions,
    the conditions' labels and places and the stimuli's tags, as a session, ``serve`` or ``merge`` does when it
    opens the database with its design (what is stored already is kept). For a database made or upgraded
    before it stored them (criterion labels: schema 7). ``design`` must be the one the database was made for
    (:func:`~studyapp.study.design.load_design_of`: one-line :class:`~studyapp.errors.InputError` otherwise)."""
    from studyapp.study.design import load_design_of

    rdb, owned = _open(db)
    try:
        rdb.store_design_metadata(load_design_of(design, rdb.design_hash))
    finally:
        if owned:
            rdb.close()


def criteria_unlabelled(db: str | Path | ResultsDB) -> bool:
    """Whether the database stores no criteria (a database upgraded from schema 6 that no session, ``serve`` or
    ``merge`` has opened with its design since): its export names every criterion by its id."""
    rdb, owned = _open(db)
    try:
        return not rdb.criteria()
    finally:
        if owned:
            rdb.close()


def questionnaire_dataframe(db: str | Path | ResultsDB) -> pd.DataFrame:
    """Questionnaire answers: participant, item, scale, kind, value (Likert points and number answers;
    empty for the rest), text (the answer to text and choice items; a JSON list when several may be
    chosen), design_hash, app_version."""
    rdb, owned = _open(db)
    try:
        rows = rdb.questionnaire()
    finally:
        if owned:
            rdb.close()
    out = []
    for r in rows:
        likert = (r.get("kind") or "likert") in ("likert", "number")  # numeric answers
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
        for table in ("study", "stimuli", "conditions", "criteria", "participants", "sessions", "trials",
                      "trial_slots", "responses", "judgements", "plays", "questionnaire"):
            out[table] = [dict(r) for r in con.execute(f"SELECT * FROM {table}")]
    finally:
        if owned:
            rdb.close()
    return json.loads(json.dumps(out, default=str))
