"""Row checksums of the results database: a bit flip anywhere in a real file is reported, never exported.

The database comes from real bot sessions; every case flips one bit of a copy and then reads it the way
``export``, ``merge`` and ``results-analysis`` do. Each flip must be harmless (every table reads back
exactly as before) or reported as one clear error; never a traceback, never changed data.
``STUDYAPP_BITFLIPS=5000`` runs a larger sample.
"""
from __future__ import annotations

import logging
import math
import os
import random
import shutil
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest

from results_analysis import integrity
from results_analysis.errors import AnalysisInputError
from results_analysis.loader import load_questionnaire, load_results
from studyapp.bots.session_driver import run_bot_session
from studyapp.errors import InputError
from studyapp.study import row_checksums, storage
from studyapp.study.design import load_design
from studyapp.study.export import export_dataframe, questionnaire_dataframe
from studyapp.study.storage import ResultsDB
from fixtures.synthetic import write_synthetic_study

N_FLIPS = int(os.environ.get("STUDYAPP_BITFLIPS", "240"))


@pytest.fixture(scope="module")
def bot_db(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("flips")
    design = load_design(write_synthetic_study(folder, n_stimuli=4, attention_check=True, questionnaire=True),
                         check_files=False)
    path = folder / "r.sqlite"
    with ResultsDB(path, design) as db:
        run_bot_session(design, db, "P1", "ordered", 1, groups={"device": "vr"})
        run_bot_session(design, db, "P2", "random", 2, groups={"device": "desktop"})
        db.add_bundle_key("b" * 64, {"roster": {"R1": 0}, "conditions": {"c1": "synced"}})
    assert not Path(f"{path}-wal").exists()  # closed: everything is in the one file
    return path


def _dump(path: Path) -> dict:
    """Everything a reader of the file gets: every table through studyapp, and the two tidy exports."""
    with ResultsDB(path, create=False) as db:
        con = db.connection
        tables = {t: sorted(map(repr, (tuple(r) for r in con.execute(f'SELECT * FROM "{t}"'))))
                  for t in row_checksums.covered_tables(con)}
        tidy = export_dataframe(db).to_csv(index=False)
        quest = questionnaire_dataframe(db).to_csv(index=False)
    return {"tables": tables, "tidy": tidy, "questionnaire": quest}


def _analysis(path: Path) -> tuple[str, str]:
    return (load_results(path).to_csv(index=False), load_questionnaire(path).to_csv(index=False))


def test_both_implementations_agree_on_a_real_database_and_on_every_kind_of_value(bot_db: Path, tmp_path) -> None:
    path = tmp_path / "r.sqlite"
    shutil.copy(bot_db, path)
    con = sqlite3.connect(path)
    # every SQLite storage class and the awkward cases: NaN, -0.0, huge integers, NUL and non-UTF-8 bytes
    con.execute("CREATE TABLE edge (a, b, c)")
    con.executemany("INSERT INTO edge VALUES (?, ?, ?)", [
        (None, 0, -0.0), (math.nan, 2 ** 63 - 1, -2 ** 63), ("é\x00z", b"\x00\xff", 1e308), (1.5, "", b"")])
    con.execute("INSERT INTO edge VALUES (CAST(X'C3FF41' AS TEXT), 'x', 'y')")  # stored text that is not UTF-8
    con.commit()
    tables = row_checksums.covered_tables(con)
    assert {"trials", "responses", "questionnaire", "participants", "bundles", "edge"} <= set(tables)
    n = 0
    for table in tables:
        ours = dict(row_checksums.row_digests(con, table))
        assert ours == integrity.table_checksums(con, table), table
        n += len(ours)
    assert n > 100
    # and both match the stored checksums of the real rows
    stored = {(t, r): d for t, r, d in con.execute("SELECT tbl, rid, sha256 FROM row_checksums")}
    assert stored == {(t, r): d for t in tables if t != "edge" for r, d in row_digests_of(con, t)}
    con.close()


def row_digests_of(con: sqlite3.Connection, table: str):
    return integrity.table_checksums(con, table).items()


def test_the_encoding_is_the_documented_one() -> None:
    """One row worked by hand from the docstring, so neither implementation can drift with the other."""
    import hashlib
    import struct

    def f(b: bytes) -> bytes:
        return struct.pack(">I", len(b)) + b

    con = sqlite3.connect(":memory:")
    con.execute("CREATE TABLE t (name TEXT, n INTEGER, x REAL, empty)")
    con.execute("INSERT INTO t VALUES ('clip04', 7, 0.5, NULL)")
    want = hashlib.sha256(b"studyapp-row-v1" + f(b"t") + f(b"1") + f(b"name") + f(b"text") + f(b"clip04")
                          + f(b"n") + f(b"integer") + f(b"7") + f(b"x") + f(b"real") + f(struct.pack(">d", 0.5))
                          + f(b"empty") + f(b"null") + f(b"")).hexdigest()
    assert dict(row_checksums.row_digests(con, "t")) == {1: want} == integrity.table_checksums(con, "t")


def test_an_edited_value_is_reported_by_export_merge_and_the_analysis(bot_db: Path, tmp_path) -> None:
    path = tmp_path / "r.sqlite"
    shutil.copy(bot_db, path)
    with sqlite3.connect(path) as con:  # what a bit flip does: clip04 becomes clkp04
        changed = con.execute("UPDATE trials SET stimulus = 'clkp04' WHERE participant = 'P2' AND trial_index = 2")
        assert changed.rowcount == 1
    con.close()
    with pytest.raises(InputError, match=r"damaged: table trials, row participant 'P2', trial_index 2: the row "
                                         r"does not match its checksum"):
        export_dataframe(path)
    with pytest.raises(AnalysisInputError, match="damaged: table trials, rowid"):
        load_results(path)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    for cmd in (["-m", "studyapp.cli", "export", str(path), "--csv", str(tmp_path / "out.csv")],
                ["-m", "studyapp.cli", "merge", str(path), str(tmp_path / "none.zip")],
                ["-m", "results_analysis.cli", str(path), "--out", str(tmp_path / "rep")]):
        run = subprocess.run([sys.executable, *cmd], capture_output=True, text=True, env=env, timeout=300)
        assert run.returncode != 0 and "damaged" in run.stderr and "Traceback" not in run.stderr, (cmd, run.stderr)
        assert not (tmp_path / "out.csv").exists()


def test_a_deleted_row_and_a_row_added_by_another_program_are_reported(bot_db: Path, tmp_path) -> None:
    path = tmp_path / "r.sqlite"
    shutil.copy(bot_db, path)
    with sqlite3.connect(path) as con:
        con.execute("DELETE FROM questionnaire WHERE participant = 'P1' AND item = 'comments'")
        con.execute("INSERT INTO stimuli (id, tags) VALUES ('extra', '{}')")
    con.close()
    with pytest.raises(InputError) as err:
        ResultsDB(path, create=False)
    assert "table questionnaire, rowid" in str(err.value) and "is missing" in str(err.value)
    assert "table stimuli, row id 'extra': the row has no checksum" in str(err.value)
    assert len(integrity.damaged_rows(sqlite3.connect(path))) == 2


def _flip_positions(data: bytes, n: int, seed: int) -> list[int]:
    """Seeded bit positions: half anywhere in the file, half in bytes in use (non-zero: cells, headers)."""
    rng = random.Random(seed)
    used = [i for i, b in enumerate(data) if b]
    anywhere = [rng.randrange(len(data) * 8) for _ in range(n // 2)]
    return anywhere + [rng.choice(used) * 8 + rng.randrange(8) for _ in range(n - n // 2)]


def test_every_single_bit_flip_is_harmless_or_reported(bot_db: Path, tmp_path) -> None:
    data = bot_db.read_bytes()
    baseline, base_analysis = _dump(bot_db), _analysis(bot_db)
    outcome = {"harmless": 0, "reported": 0}
    silent, crashed = [], []
    case = tmp_path / "case.sqlite"
    for bit in _flip_positions(data, N_FLIPS, seed=16):
        flipped = bytearray(data)
        flipped[bit // 8] ^= 1 << (bit % 8)
        for suffix in ("", "-wal", "-shm"):
            Path(f"{case}{suffix}").unlink(missing_ok=True)
        case.write_bytes(flipped)
        try:
            got = _dump(case)
        except InputError:
            got = None
        except Exception as exc:  # noqa: BLE001 - a traceback is exactly what this test looks for
            crashed.append(f"byte {bit // 8} bit {bit % 8}: {type(exc).__name__}: {exc}")
            continue
        try:
            analysed = _analysis(case)
        except AnalysisInputError:
            analysed = None
        except Exception as exc:  # noqa: BLE001
            crashed.append(f"analysis, byte {bit // 8} bit {bit % 8}: {type(exc).__name__}: {exc}")
            continue
        if got is None:
            outcome["reported"] += 1
            if analysed is not None and analysed != base_analysis:
                silent.append(f"analysis read changed data at byte {bit // 8} bit {bit % 8}")
        elif got != baseline or (analysed is not None and analysed != base_analysis):
            silent.append(f"byte {bit // 8} bit {bit % 8}: changed data read without an error")
        else:
            outcome["harmless"] += 1
    print(f"{N_FLIPS} single-bit flips in a {len(data)}-byte database: {outcome}")
    assert not crashed, crashed[:5]
    assert not silent, silent[:5]
    assert outcome["reported"] > N_FLIPS // 4  # the flips really hit data


@pytest.mark.parametrize("table,column", [("judgements", "reasons"), ("trials", "slot_middle"),
                                          ("responses", "rank"), ("questionnaire", "value")])
def test_a_damaged_column_name_is_reported_when_opened(bot_db: Path, tmp_path, table, column) -> None:
    """One flipped bit in a table's definition renames a column: SQLite's integrity check passes, and the
    first query naming the column failed with an SQL error (fresh-clone CI, byte 79810: 'no such column:
    j.reasons'). Opening the file now says which column is gone."""
    path = tmp_path / "r.sqlite"
    shutil.copy(bot_db, path)
    flipped = column[:-1] + chr(ord(column[-1]) ^ 1)  # one bit of the name's last letter: still a name
    with sqlite3.connect(path) as con:
        sql = con.execute("SELECT sql FROM sqlite_master WHERE name = ?", (table,)).fetchone()[0]
        damaged = sql.replace(f"{column} ", f"{flipped} ", 1)
        assert damaged != sql
        con.execute("PRAGMA writable_schema = ON")
        con.execute("UPDATE sqlite_master SET sql = ? WHERE name = ?", (damaged, table))
    with pytest.raises(InputError, match=f"table {table} has no column {column}: the file is damaged"):
        ResultsDB(path, create=False)
    for read in (load_results, load_questionnaire):  # the analysis reads the file itself: one line too, or data
        try:
            read(path)
        except AnalysisInputError:
            pass


def test_a_schema_3_database_is_upgraded_in_place_with_checksums(bot_db: Path, tmp_path, caplog) -> None:
    path = tmp_path / "r.sqlite"
    shutil.copy(bot_db, path)
    with sqlite3.connect(path) as con:  # what studyapp wrote before labels (4) and checksums (5)
        con.execute(f"DROP TABLE {row_checksums.TABLE}")
        con.execute("ALTER TABLE conditions DROP COLUMN label")
        con.execute("DROP TABLE criteria")  # added by 7
        for table in ("trial_slots", "judgements"):  # added by 6
            con.execute(f"DROP TABLE {table}")
        for column in ("block", "paradigm"):  # added by 6
            con.execute(f"ALTER TABLE trials DROP COLUMN {column}")
        con.execute("UPDATE schema_version SET version = 3")
    con.close()
    before = export_dataframe_raw(path)
    with caplog.at_level(logging.INFO, logger="studyapp.study.storage"):
        with ResultsDB(path, create=False) as db:
            assert db.connection.execute("SELECT version FROM schema_version").fetchone()[0] == storage.SCHEMA_VERSION
            assert row_checksums.verify(db.connection) == []
            n = db.connection.execute(f"SELECT COUNT(*) FROM {row_checksums.TABLE}").fetchone()[0]
    assert "upgraded the results database from schema version 3" in caplog.text
    assert n == sum(len(integrity.table_checksums(sqlite3.connect(path), t))
                    for t in row_checksums.covered_tables(sqlite3.connect(path)))
    assert export_dataframe(path).to_csv() == before
    assert integrity.damaged_rows(sqlite3.connect(path)) == []


def export_dataframe_raw(path: Path) -> str:
    from results_analysis.sqlite_schema import tidy_table

    with sqlite3.connect(path) as con:
        return tidy_table(con, path).to_csv()


def test_a_column_added_by_a_later_migration_is_covered_with_no_code_change(bot_db: Path, tmp_path,
                                                                             monkeypatch) -> None:
    """Like ``conditions.label`` was: the next migration adds a column; every row is resealed, and the new column
    is inside the checksum (editing it is reported)."""
    path = tmp_path / "r.sqlite"
    shutil.copy(bot_db, path)
    v = storage.SCHEMA_VERSION
    monkeypatch.setattr(storage, "_MIGRATIONS", {**storage._MIGRATIONS,
                                                 v: ("ALTER TABLE conditions ADD COLUMN note TEXT DEFAULT 'x'",)})
    monkeypatch.setattr(storage, "SCHEMA_VERSION", v + 1)
    with ResultsDB(path, create=False) as db:
        assert row_checksums.verify(db.connection) == []
        db.connection.execute("SELECT note FROM conditions").fetchall()
    with sqlite3.connect(path) as con:
        con.execute("UPDATE conditions SET note = 'y' WHERE position = 0")
    con.close()
    with pytest.raises(InputError, match="table conditions, row id '.+': the row does not match"):
        ResultsDB(path, create=False)
