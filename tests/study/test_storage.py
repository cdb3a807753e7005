"""ResultsDB: durability settings, row assignment, atomic answers, and refusing wrong or damaged files."""
from __future__ import annotations

import os
import sqlite3
from pathlib import Path

import pytest

from studyapp import __version__
from studyapp.errors import InputError
from studyapp.study.storage import DuplicateAnswerError, Response, ResultsDB, TrialRecord, now_iso


def _trial(pid: str, k: int) -> TrialRecord:
    return TrialRecord(participant=pid, trial_index=k, stimulus=f"s{k}", is_practice=False, is_attention_check=False,
                       slots=("a", "b", "c"), answered_at=now_iso(), plays=1)


def _ranks(order=(1, 2, 3)) -> list[Response]:
    return [Response(crit, cond, slot, r) for crit in ("realism", "diversity")
            for slot, (cond, r) in enumerate(zip("abc", order))]


def test_pragmas_and_stamps(tmp_path: Path) -> None:
    db = ResultsDB(tmp_path / "r.sqlite", design_hash="h1", title="T")
    con = db.connection
    assert con.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    assert con.execute("PRAGMA synchronous").fetchone()[0] == 2  # FULL
    assert con.execute("PRAGMA foreign_keys").fetchone()[0] == 1
    db.add_participant("P1", n_rows=3)
    db.save_trial(_trial("P1", 0), _ranks())
    for table in ("participants", "trials", "responses"):
        stamps = {tuple(r) for r in con.execute(f"SELECT design_hash, app_version FROM {table}")}
        assert stamps == {("h1", __version__)}, table
    db.close()


def test_database_locked_by_another_program_is_named_as_such(tmp_path: Path, monkeypatch) -> None:
    """A lock held elsewhere is "in use", never "damaged, start a new one" (which would split the study)."""
    path = tmp_path / "r.sqlite"
    db = ResultsDB(path, design_hash="h1", title="T")
    db.add_participant("P1", n_rows=3)
    db.save_trial(_trial("P1", 0), _ranks())
    db.close()
    other = sqlite3.connect(path, isolation_level=None)  # e.g. a database browser in rollback mode, mid-write
    other.execute("PRAGMA journal_mode=DELETE")
    other.execute("BEGIN EXCLUSIVE")
    monkeypatch.setattr(ResultsDB, "LOCK_TIMEOUT_S", 0.2)
    with pytest.raises(InputError, match="in use by another program") as err:
        ResultsDB(path, design_hash="h1")
    assert "damaged" not in str(err.value) and "new one" not in str(err.value)
    other.execute("ROLLBACK")
    other.close()
    again = ResultsDB(path, design_hash="h1")
    assert again.connection.execute("SELECT COUNT(*) FROM responses").fetchone()[0] == 6
    again.close()


def test_rows_go_to_the_least_used_row(tmp_path: Path) -> None:
    db = ResultsDB(tmp_path / "r.sqlite", design_hash="h", title="T")
    assert [db.add_participant(f"P{i}", n_rows=3).latin_row for i in range(3)] == [0, 1, 2]
    assert db.add_participant("X", n_rows=3, row=0).latin_row == 0
    # rows 1 and 2 now have one participant each, row 0 has two: next is 1, then 2, then 0 again.
    assert [db.add_participant(f"Q{i}", n_rows=3).latin_row for i in range(3)] == [1, 2, 0]
    assert db.row_counts(3) == [3, 2, 2]
    with pytest.raises(InputError, match="row 5"):
        db.add_participant("bad", n_rows=3, row=5)
    db.close()
    # the rows are stored, not recomputed: a reopened database gives the same rows
    again = ResultsDB(tmp_path / "r.sqlite", design_hash="h")
    assert again.participant("Q0").latin_row == 1
    again.close()


def test_answer_is_all_or_nothing_and_never_overwritten(tmp_path: Path) -> None:
    db = ResultsDB(tmp_path / "r.sqlite", design_hash="h", title="T")
    db.add_participant("P1", n_rows=1)
    db.save_trial(_trial("P1", 0), _ranks((1, 2, 3)))
    with pytest.raises(DuplicateAnswerError):
        db.save_trial(_trial("P1", 0), _ranks((3, 2, 1)))
    assert [r["rank"] for r in db.responses("P1") if r["criterion"] == "realism"] == [1.0, 2.0, 3.0]
    # a trial whose last rank violates a constraint leaves neither the trial nor its other ranks behind
    bad = _ranks() + [Response("realism", "a", 7, 1)]
    with pytest.raises(sqlite3.IntegrityError):
        db.save_trial(_trial("P1", 1), bad)
    assert db.answered_trials("P1") == {0}
    assert len(db.responses("P1")) == 6
    db.close()


def test_other_design_is_refused(tmp_path: Path) -> None:
    ResultsDB(tmp_path / "r.sqlite", design_hash="a" * 64, title="T").close()
    with pytest.raises(InputError) as err:
        ResultsDB(tmp_path / "r.sqlite", design_hash="b" * 64)
    assert str(tmp_path / "r.sqlite") in str(err.value) and "another design" in str(err.value)


def test_not_sqlite_and_foreign_schema_are_refused(tmp_path: Path) -> None:
    text = tmp_path / "notes.sqlite"
    text.write_text("participant,rank\nP1,1\n")
    with pytest.raises(InputError, match="not an SQLite database") as err:
        ResultsDB(text, design_hash="h")
    assert str(text) in str(err.value)
    other = tmp_path / "other.sqlite"
    with sqlite3.connect(other) as con:
        con.execute("CREATE TABLE answers (x)")
    with pytest.raises(InputError, match="not a studyapp results database"):
        ResultsDB(other, design_hash="h")
    old = tmp_path / "old.sqlite"
    ResultsDB(old, design_hash="h", title="T").close()
    with sqlite3.connect(old) as con:
        con.execute("UPDATE schema_version SET version = 99")
    with pytest.raises(InputError, match="schema version 99"):
        ResultsDB(old, design_hash="h")


def test_overwritten_bytes_are_detected(tmp_path: Path) -> None:
    path = tmp_path / "r.sqlite"
    db = ResultsDB(path, design_hash="h", title="T")
    db.add_participant("P1", n_rows=1)
    for k in range(40):
        db.save_trial(_trial("P1", k), _ranks())
    db.close()  # checkpoints the WAL into the main file
    assert not Path(str(path) + "-wal").exists() or os.path.getsize(str(path) + "-wal") == 0
    size = path.stat().st_size
    page = 4096
    assert size > 4 * page
    with open(path, "r+b") as fh:  # scribble over the middle of two b-tree pages
        for p in (2, size // page - 1):
            fh.seek(p * page + 8)
            fh.write(b"\xa5" * 600)
    with pytest.raises(InputError) as err:
        ResultsDB(path, design_hash="h")
    assert str(path) in str(err.value) and "damaged" in str(err.value)
    # one line, whatever SQLite found: its report can be one row holding a line per damaged cell
    assert "\n" not in str(err.value) and "*** in database" not in str(err.value)


def test_missing_file_without_design(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="not found"):
        ResultsDB(tmp_path / "nope.sqlite", create=False)


def test_database_left_empty_by_a_killed_creation_is_created_again(tmp_path: Path) -> None:
    path = tmp_path / "r.sqlite"
    con = sqlite3.connect(path)
    con.execute("PRAGMA journal_mode=WAL")  # writes the header; the schema transaction never ran
    con.close()
    assert path.stat().st_size > 0
    db = ResultsDB(path, design_hash="h", title="T")
    assert db.add_participant("P1", n_rows=2).latin_row == 0
    db.close()
    with pytest.raises(InputError, match="empty"):
        empty = tmp_path / "e.sqlite"
        sqlite3.connect(empty).execute("PRAGMA journal_mode=WAL").fetchone()
        ResultsDB(empty)


def test_concurrent_processes_keep_rows_balanced(tmp_path: Path) -> None:
    """Three lab PCs registering participants on one database at once: the least-used-row choice is atomic."""
    import subprocess
    import sys

    path = tmp_path / "shared.sqlite"
    ResultsDB(path, design_hash="h", title="T").close()
    code = ("import sys; from studyapp.study.storage import ResultsDB\n"
            "db = ResultsDB(sys.argv[1], design_hash='h')\n"
            "for k in range(8): db.add_participant(f'{sys.argv[2]}{k}', n_rows=6)\n"
            "db.close()\n")
    procs = [subprocess.Popen([sys.executable, "-c", code, str(path), name]) for name in ("A", "B", "C")]
    assert [p.wait(timeout=120) for p in procs] == [0, 0, 0]
    db = ResultsDB(path, design_hash="h")
    assert db.row_counts(6) == [4] * 6
    assert len(db.participants()) == 24
    db.close()


def test_conditions_keep_their_label_and_a_schema_3_database_is_upgraded_with_none(tmp_path: Path) -> None:
    """Schema 4 added each condition's design label; an older database gets the column, empty."""
    from types import SimpleNamespace as NS

    from studyapp.study.export import export_dataframe
    from studyapp.study.storage import SCHEMA_VERSION

    design = NS(design_hash="ab12", title="T", stimuli=[NS(id="s0", tags={})],
                conditions=[NS(id="b", label="Baseline"), NS(id="a", label=None), NS(id="c", label="Ours")])
    path = tmp_path / "r.sqlite"
    with ResultsDB(path, design) as db:
        db.add_participant("P1", n_rows=1)
        db.save_trial(_trial("P1", 0), _ranks())
        rows = db.connection.execute("SELECT id, position, label FROM conditions ORDER BY position").fetchall()
    assert [tuple(r) for r in rows] == [("b", 0, "Baseline"), ("a", 1, None), ("c", 2, "Ours")]
    with sqlite3.connect(path) as con:  # what studyapp wrote before labels (4) and row checksums (5): schema 3
        con.execute("DROP TABLE row_checksums")
        con.execute("ALTER TABLE conditions DROP COLUMN label")
        con.execute("DROP TABLE criteria")  # added by 7
        for table in ("trial_slots", "judgements"):  # added by 6
            con.execute(f"DROP TABLE {table}")
        for column in ("block", "paradigm"):  # added by 6
            con.execute(f"ALTER TABLE trials DROP COLUMN {column}")
        con.execute("UPDATE schema_version SET version = 3")
    df = export_dataframe(path)  # opening upgrades it in place
    with sqlite3.connect(path) as con:
        assert con.execute("SELECT version FROM schema_version").fetchone()[0] == SCHEMA_VERSION == 7
        assert con.execute("SELECT id, label FROM conditions ORDER BY position").fetchall() == [
            ("b", None), ("a", None), ("c", None)]
    # no label recorded: the analysis's name is the id; the design order stays
    assert sorted(set(zip(df["condition"], df["condition_label"], df["condition_position"]))) == [
        ("a", "a", 1), ("b", "b", 0), ("c", "c", 2)]
