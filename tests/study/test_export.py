"""The tidy export: one row per participant x trial x criterion x condition, checked against the raw tables."""
from __future__ import annotations

import sqlite3
from pathlib import Path

import pandas as pd
import pytest

from studyapp.bots.session_driver import run_bot_session
from studyapp.study.design import load_design
from studyapp.study.export import CORE_COLUMNS, export_dataframe, questionnaire_dataframe
from studyapp.study.storage import ResultsDB
from fixtures.synthetic import write_synthetic_study


@pytest.fixture(scope="module")
def results(tmp_path_factory) -> tuple[Path, object]:
    folder = tmp_path_factory.mktemp("export")
    design = load_design(write_synthetic_study(folder, n_stimuli=4, attention_check=True, questionnaire=True),
                         check_files=False)
    db_path = folder / "r.sqlite"
    db = ResultsDB(db_path, design)
    run_bot_session(design, db, "P1", "ordered", 1, groups={"device": "vr"})
    run_bot_session(design, db, "P2", "random", 2, groups={"device": "desktop"})
    db.close()
    return db_path, design


def test_long_table_shape_columns_and_values(results) -> None:
    db_path, design = results
    df = export_dataframe(db_path)
    n_trials = 1 + 4 + 1  # practice + rated + attention check
    assert len(df) == 2 * n_trials * 3 * 3
    assert list(df.columns[: len(CORE_COLUMNS)]) == list(CORE_COLUMNS)
    assert list(df.columns[-2:]) == ["design_hash", "app_version"]
    assert {"speaker", "device", "ordering_version"} <= set(df.columns)
    assert (df["design_hash"] == design.design_hash).all()
    # tags and groups come from the design and the participants
    tags = {s.id: s.tags["speaker"] for s in design.stimuli}
    assert (df["speaker"] == df["stimulus"].map(tags)).all()
    assert set(zip(df["participant"], df["device"])) == {("P1", "vr"), ("P2", "desktop")}
    assert (df["ordering_version"] == "v1").all()
    # each block ranks the three conditions 1, 2, 3
    blocks = df.groupby(["participant", "trial_index", "criterion"])
    assert (blocks["rank"].apply(sorted).map(tuple) == (1.0, 2.0, 3.0)).all()
    assert (blocks["condition"].nunique() == 3).all()
    # the ordered bot ranks conditions in design order: synced 1, lagged 2, static 3, on every criterion
    p1 = df[df["participant"] == "P1"]
    assert (p1["rank"] == p1["condition"].map({"synced": 1.0, "lagged": 2.0, "static": 3.0})).all()
    # flags: practice kept and flagged; attention_passed only on attention checks
    assert df.loc[df["is_practice"], "trial_index"].eq(0).all()
    assert df.loc[~df["is_attention_check"], "attention_passed"].isna().all()
    assert df.loc[(df["participant"] == "P1") & df["is_attention_check"], "attention_passed"].eq(True).all()
    assert len(export_dataframe(db_path, include_practice=False)) == 2 * (n_trials - 1) * 9


def test_criteria_keep_the_design_order(results, tmp_path: Path) -> None:
    db_path, design = results
    wanted = [c.id for c in design.criteria]
    assert wanted != sorted(wanted), "the fixture must list criteria out of alphabetical order"
    df = export_dataframe(db_path)
    assert list(dict.fromkeys(df["criterion"])) == wanted
    # the analysis takes its table order from the export
    from results_analysis import load_results, run_analysis

    df.to_csv(tmp_path / "r.csv", index=False)
    assert list(run_analysis(load_results(tmp_path / "r.csv"), n_boot=50).criteria) == wanted
    # and the same when the analysis reads the database itself
    assert list(run_analysis(load_results(db_path), n_boot=50).criteria) == wanted


def test_export_matches_raw_tables(results) -> None:
    db_path, _ = results
    df = export_dataframe(db_path)
    con = sqlite3.connect(db_path)
    raw = con.execute("SELECT r.condition, r.criterion, SUM(r.rank), COUNT(*) FROM responses r "
                      "GROUP BY r.condition, r.criterion").fetchall()
    slots = con.execute("SELECT participant, trial_index, slot_left, slot_middle, slot_right FROM trials").fetchall()
    con.close()
    got = df.groupby(["condition", "criterion"])["rank"].agg(["sum", "count"])
    for cond, crit, total, n in raw:
        assert got.loc[(cond, crit), "sum"] == total and got.loc[(cond, crit), "count"] == n
    # the slot column says where the condition was shown
    where = {(p, t): (a, b, c) for p, t, a, b, c in slots}
    assert all(where[(r.participant, r.trial_index)][r.slot] == r.condition for r in df.itertuples())


def test_csv_round_trip_through_results_analysis(results, tmp_path: Path) -> None:
    from results_analysis.loader import load_results

    db_path, _ = results
    df = export_dataframe(db_path)
    out = tmp_path / "r.csv"
    df.to_csv(out, index=False)
    back = load_results(out)
    assert len(back) == len(df)
    assert back["rank"].tolist() == df["rank"].astype(float).tolist()
    assert back["attention_passed"][df["is_attention_check"].to_numpy()].tolist() == \
        df.loc[df["is_attention_check"], "attention_passed"].astype(bool).tolist()


def test_questionnaire_table(results) -> None:
    db_path, _ = results
    q = questionnaire_dataframe(db_path)
    assert len(q) == 2 * 3
    likert = q[q["kind"] == "likert"]
    assert likert["value"].between(1, 7).all() and (likert["scale"] == "experience").all()
    text = q[q["kind"] == "text"]
    assert text["value"].isna().all() and (text["text"] == "(scripted participant)").all()
    assert isinstance(q, pd.DataFrame)


def test_labels_order_title_and_questionnaire_travel_with_the_long_table(tmp_path: Path) -> None:
    """What the report needs besides the ranks is in every row, checked against the raw tables."""
    path = write_synthetic_study(tmp_path / "s", n_stimuli=2, questionnaire=True, seconds=0.5)
    # labels on two of the three conditions; the design lists them synced, lagged, static
    path.write_text(path.read_text().replace('id = "lagged"\n', 'id = "lagged"\nlabel = "Late, by 0.5 s"\n')
                    .replace('id = "static"\n', 'id = "static"\nlabel = "Still"\n'))
    design = load_design(path, check_files=False)
    db_path = tmp_path / "r.sqlite"
    with ResultsDB(db_path, design) as db:
        run_bot_session(design, db, "P1", "random", 1)
        run_bot_session(design, db, "P2", "random", 2)
    df = export_dataframe(db_path)
    with sqlite3.connect(db_path) as con:
        stored = {i: (lb, p) for i, lb, p in con.execute("SELECT id, label, position FROM conditions")}
        title = con.execute("SELECT title FROM study").fetchone()[0]
        answers = con.execute("SELECT participant, item, scale, kind, value FROM questionnaire").fetchall()
    assert stored == {"synced": (None, 0), "lagged": ("Late, by 0.5 s", 1), "static": ("Still", 2)}
    expect_label = {"synced": "synced", "lagged": "Late, by 0.5 s", "static": "Still"}
    assert (df["condition_label"] == df["condition"].map(expect_label)).all()
    assert (df["condition_position"] == df["condition"].map({"synced": 0, "lagged": 1, "static": 2})).all()
    assert title == design.title and (df["study_title"] == title).all()
    rated = [a for a in answers if a[3] != "text"]
    assert rated and len(rated) < len(answers)  # the text item stays out of the table
    for participant, item, scale, _, value in rated:
        column = df.loc[df["participant"] == participant, f"questionnaire:{scale or ''}:{item}"]
        assert (column == value).all(), (participant, item)
    assert not [c for c in df.columns if c.startswith("questionnaire:") and c.endswith(":comments")]
    # the CSV carries them as written
    df.to_csv(tmp_path / "r.csv", index=False)
    back = pd.read_csv(tmp_path / "r.csv")
    assert back["condition_label"].tolist() == df["condition_label"].tolist()
    assert list(back.columns[-3:]) == ["study_title", "design_hash", "app_version"]


def test_only_likert_answers_become_questionnaire_columns(tmp_path: Path) -> None:
    """A number item (age) and a choice item are not on a rating scale: they stay out of the tidy table (and so
    out of the report's scale statistics), while the questionnaire export keeps them."""
    path = write_synthetic_study(tmp_path / "s", n_stimuli=2, questionnaire=True, seconds=0.5)
    path.write_text(path.read_text() + '''
[[questionnaire]]
id = "age"
kind = "number"
text = "Your age?"
min = 18
max = 99
integer = true

[[questionnaire]]
id = "hand"
kind = "choice"
text = "Which hand do you write with?"
options = ["left", "right"]
''')
    design = load_design(path, check_files=False)
    db_path = tmp_path / "r.sqlite"
    with ResultsDB(db_path, design) as db:
        run_bot_session(design, db, "P1", "random", 1)
    with sqlite3.connect(db_path) as con:
        kinds = {i: k for i, k in con.execute("SELECT item, kind FROM questionnaire")}
    assert kinds["age"] == "number" and kinds["hand"] == "choice" and "likert" in kinds.values()
    columns = {c.rsplit(":", 1)[1] for c in export_dataframe(db_path).columns if c.startswith("questionnaire:")}
    assert columns == {i for i, k in kinds.items() if k == "likert"}
    assert {"age", "hand"} <= set(questionnaire_dataframe(db_path)["item"])
