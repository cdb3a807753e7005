"""The results model on both backends: an SQLite file and a real PostgreSQL server (Debian's binaries, started
once per test session by the ``postgres_server`` fixture in tests/conftest.py).

Each test that takes ``results_target`` runs on both. Checked against the database itself (raw sqlite3/psycopg
reads), never only through ResultsDB: answers stored once and never overwritten, Latin-square rows balanced
under concurrent writers, tampered rows reported by their checksums, the tidy export identical on both, and a
SIGKILLed writer losing no committed answer.
"""
from __future__ import annotations

import os
import queue
import signal
import sqlite3
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import pandas as pd
import pytest

from fixtures.synthetic import write_synthetic_study
from studyapp.errors import InputError
from studyapp.study import row_checksums, sql_backend
from studyapp.study.storage import DuplicateAnswerError, Response, ResultsDB, TrialRecord, now_iso, open_results

CLI = [sys.executable, "-m", "studyapp.cli"]


def _raw(target: Path | str, sql: str, params: tuple = ()) -> list[tuple]:
    """Run one statement on the database directly (not through studyapp); its rows."""
    if isinstance(target, Path):
        con = sqlite3.connect(target, isolation_level=None)
        try:
            return con.execute(sql, params).fetchall()
        finally:
            con.close()
    import psycopg

    with psycopg.connect(target, autocommit=True) as con:
        cur = con.execute(sql.replace("?", "%s"), params or None)
        return cur.fetchall() if cur.description else []


def _trial(pid: str, index: int, session: int) -> tuple[TrialRecord, list[Response]]:
    rec = TrialRecord(pid, index, f"clip{index:02d}", index == 0, False, ("a", "b", "c"), now_iso(),
                      response_time_s=1.25 + index, plays=1, refresh_hz=59.94, session=session, samples=(1, 2, None))
    return rec, [Response("realism", c, s, r) for s, (c, r) in enumerate(zip("abc", (2.0, 1.0, 3.0)))]


def test_every_method_stores_the_same_rows_on_both_backends(results_target: Path | str) -> None:
    db = open_results(results_target, design_hash="ab12" * 16, title="Demo")
    assert db.backend == ("sqlite" if isinstance(results_target, Path) else "postgresql")
    assert [db.add_participant(f"P{i}", n_rows=4).latin_row for i in range(6)] == [0, 1, 2, 3, 0, 1]
    with pytest.raises(Exception, match="already in"):
        db.add_participant("P0", n_rows=4)
    s = db.start_session("P0", {"os": "linux"})
    db.update_session_machine(s, {"gl": "4.6"})
    play = db.start_play("P0", 0, s)
    db.finish_play(play, True)
    for i in range(3):
        db.save_trial(*_trial("P0", i, s))
    with pytest.raises(DuplicateAnswerError):
        db.save_trial(*_trial("P0", 1, s))
    db.save_questionnaire("P0", {"age": 3, "note": "fine"}, {"note": ("text", None)})
    db.set_status("P0", "done")
    db.update_groups("P1", {"device": "vr"})
    db.add_bundle_key("h1", {"roster": {"R01": 0}})
    db.add_bundle_key("h1", {"roster": {"R02": 1}})  # replaces the first
    assert db.discard_unstarted("P5") and not db.discard_unstarted("P0")
    db.end_session(s)
    db.close()

    db = open_results(results_target, create=False)  # reopened: every row checked against its checksum
    try:
        assert row_checksums.verify(db.connection) == []
        assert db.answered_trials("P0") == {0, 1, 2}
        assert db.participant("P0").status == "done" and db.participant("P1").groups == {"device": "vr"}
        assert db.row_counts(4) == [2, 1, 1, 1]
        assert db.sessions("P0")[0]["machine"] == {"os": "linux", "gl": "4.6"} and db.sessions()[0]["ended"]
        assert db.play_count("P0", 0) == 1 and db.plays("P0")[0]["completed"] == 1
        assert db.issued_remote_ids() == {"R02"}
        assert {q["item"]: q["value"] for q in db.questionnaire("P0")} == {"age": "3", "note": "fine"}
        t = db.trials("P0")[1]
        assert "rowid" not in t and t["response_time_s"] == 2.25 and t["refresh_hz"] == 59.94  # 64-bit reals
        assert (t["sample_left"], t["sample_middle"], t["sample_right"]) == (1, 2, None)
        assert [r["rank"] for r in db.responses("P0") if r["trial_index"] == 2] == [2.0, 1.0, 3.0]
    finally:
        db.close()
    # the rows as the database itself holds them
    assert _raw(results_target, "SELECT COUNT(*) FROM responses")[0][0] == 9
    assert _raw(results_target, "SELECT COUNT(*) FROM participants")[0][0] == 5


def test_a_tampered_or_foreign_row_is_reported_on_both_backends(results_target: Path | str) -> None:
    db = open_results(results_target, design_hash="cd34", title="T")
    db.add_participant("P1", n_rows=2)
    db.save_trial(*_trial("P1", 0, db.start_session("P1")))
    db.close()
    _raw(results_target, "UPDATE responses SET rank = 1.0 WHERE slot = 0")
    with pytest.raises(InputError, match=r"table responses, row participant 'P1', trial_index 0, criterion "
                                         r"'realism', slot 0: the row does not match its checksum"):
        open_results(results_target, create=False)
    _raw(results_target, "UPDATE responses SET rank = 2.0 WHERE slot = 0")  # back as it was: accepted again
    open_results(results_target, create=False).close()
    _raw(results_target, "INSERT INTO conditions (id, position) VALUES ('x', 9)")
    with pytest.raises(InputError, match=r"table conditions, row id 'x': the row has no checksum"):
        open_results(results_target, create=False)


def test_another_design_is_refused_on_both_backends(results_target: Path | str) -> None:
    open_results(results_target, design_hash="aa" * 20, title="A").close()
    with pytest.raises(InputError, match="belongs to another design"):
        open_results(results_target, design_hash="bb" * 20, title="B")


def test_concurrent_writers_never_share_a_stale_row_count(results_target: Path | str) -> None:
    """8 writers, each with its own connection, register 40 participants at once: the least-used row is chosen
    from a count no other writer can change meanwhile, so the 4 rows end up exactly 10 each. Several writers
    create the brand-new database at the same moment too, and all of them end up using one set of tables."""
    start = threading.Barrier(8)
    errors: list[BaseException] = []

    def writer(k: int) -> None:
        try:
            start.wait()
            db = open_results(results_target, design_hash="ee" * 20, title="Concurrent")
            try:
                for i in range(5):
                    db.add_participant(f"W{k}-{i}", n_rows=4)
            finally:
                db.close()
        except BaseException as exc:  # reported by the main thread
            errors.append(exc)

    threads = [threading.Thread(target=writer, args=(k,)) for k in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=120)
    assert not errors, errors
    rows = _raw(results_target, "SELECT latin_row, COUNT(*) FROM participants GROUP BY latin_row ORDER BY latin_row")
    assert rows == [(0, 10), (1, 10), (2, 10), (3, 10)]
    assert _raw(results_target, "SELECT COUNT(*) FROM study")[0][0] == 1


def test_unreachable_server_is_one_line_without_the_password() -> None:
    with socket_closed_port() as port:
        url = f"postgresql://alice:s3cret@127.0.0.1:{port}/study"
        with pytest.raises(InputError) as err:
            open_results(url, design_hash="ab", title="t")
    text = str(err.value)
    assert text.startswith(f"postgresql://alice:***@127.0.0.1:{port}/study: cannot reach the PostgreSQL server")
    assert "s3cret" not in text and "\n" not in text


class socket_closed_port:
    """A loopback port nothing listens on (bound, then released)."""

    def __enter__(self) -> int:
        import socket

        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            return int(s.getsockname()[1])

    def __exit__(self, *exc: object) -> None:
        return None


@pytest.mark.parametrize("sql, pk, expected", [
    ("INSERT OR IGNORE INTO stimuli (id, tags) VALUES (?, ?)", (),
     "INSERT INTO stimuli (id, tags) VALUES (?, ?) ON CONFLICT DO NOTHING"),
    ("INSERT OR REPLACE INTO bundles (design_hash, created, key) VALUES (?, ?, ?)", ("design_hash",),
     "INSERT INTO bundles (design_hash, created, key) VALUES (?, ?, ?) ON CONFLICT (design_hash) DO UPDATE SET "
     "created = EXCLUDED.created, key = EXCLUDED.key"),
    ("ALTER TABLE trials ADD COLUMN trial_duration_s REAL", (),
     "ALTER TABLE trials ADD COLUMN trial_duration_s DOUBLE PRECISION"),
    ("BEGIN", (), "BEGIN ISOLATION LEVEL REPEATABLE READ"),
])
def test_sqlite_statements_as_postgresql_runs_them(sql: str, pk: tuple, expected: str) -> None:
    assert sql_backend.translate(sql, pk) == expected


def test_create_table_keeps_64_bit_numbers_and_gives_every_table_a_rowid() -> None:
    ddl, name, has_rowid = sql_backend.create_table_ddl(
        "CREATE TABLE sessions (\n  id INTEGER PRIMARY KEY AUTOINCREMENT, -- one (comment)\n  t REAL,\n"
        "  n INTEGER NOT NULL\n)")
    assert name == "sessions" and has_rowid
    assert "id BIGINT GENERATED BY DEFAULT AS IDENTITY PRIMARY KEY" in ddl and "t DOUBLE PRECISION" in ddl
    assert "n BIGINT NOT NULL" in ddl and ddl.endswith("rowid BIGINT GENERATED ALWAYS AS (id) STORED\n)")
    assert sql_backend.create_table_ddl("CREATE TABLE k (a TEXT, PRIMARY KEY (a)) WITHOUT ROWID")[2] is False
    assert sql_backend.results_target("sqlite:////tmp/x.sqlite") == Path("/tmp/x.sqlite")
    assert sql_backend.results_target("postgresql://u@h/db") == "postgresql://u@h/db"


# ------------------------------------------------------------------ whole studies: export and SIGKILL
def _export_without_timing(target: Path | str) -> pd.DataFrame:
    from studyapp.study.export import export_dataframe

    # response times are measured by each run and session ids count runs: everything else must be equal
    return export_dataframe(target).drop(columns=["response_time_s", "session"])


def _cmd(design: Path, target: Path | str, pace: float) -> list[str]:
    return [*CLI, "run", str(design), "--participant", "K1", "--results", str(target), "--no-render", "--bot",
            "random", "--seed", "5", "--bot-pace", str(pace)]


def _answers(target: Path | str) -> list[tuple]:
    return _raw(target, "SELECT r.trial_index, r.criterion, r.slot, r.condition, r.rank, t.stimulus FROM responses r "
                "JOIN trials t ON t.participant = r.participant AND t.trial_index = r.trial_index "
                "WHERE r.participant = 'K1' ORDER BY r.trial_index, r.criterion, r.slot")


def _reader(stream: Any, out: queue.Queue) -> None:
    for line in iter(stream.readline, ""):
        out.put(line.rstrip("\n"))
    out.put(None)


@pytest.mark.timeout(240)
@pytest.mark.skipif(os.name != "posix", reason="SIGKILL is POSIX")
def test_sigkill_of_a_writer_on_postgresql_loses_no_committed_answer(tmp_path: Path, postgres_server) -> None:
    """`studyapp run --results postgresql://...` killed twice right after it reported an answer saved: every
    reported answer is in the database, answers are a prefix of the schedule, and the finished study holds
    exactly the answers of an uninterrupted SQLite run with the same seed (what `studyapp run` does, in this
    process). Its export (the command line, to CSV) equals that run's, and the analysis loads it."""
    from studyapp.bots import run_bot
    from studyapp.study.design import load_design
    from studyapp.study.session import prepare_participant

    design = write_synthetic_study(tmp_path / "study", n_stimuli=8, seconds=0.5, questionnaire=True)
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    reference = tmp_path / "reference.sqlite"
    loaded = load_design(design)
    with ResultsDB(reference, loaded) as ref_db:
        prepare_participant(loaded, ref_db, "K1")
        assert run_bot(loaded, ref_db, "K1", "random", 5, render=False) == 0
    url = postgres_server.new_database("killed")

    reported: set[int] = set()
    kills = 0
    while kills < 2:
        proc = subprocess.Popen(_cmd(design, url, 0.02), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                env=env)
        lines: queue.Queue = queue.Queue()
        threading.Thread(target=_reader, args=(proc.stdout, lines), daemon=True).start()
        saved_now = 0
        while True:
            line = lines.get(timeout=90)
            if line is None:
                break
            if line.startswith("saved trial"):
                reported.add(int(line.split()[-1]))
                saved_now += 1
                if saved_now == 2:  # the process has committed answers of its own: kill it mid-study
                    os.kill(proc.pid, signal.SIGKILL)
                    kills += 1
                    break
        proc.wait(timeout=30)
        proc.stdout.close()
        proc.stderr.close()
        assert proc.returncode == -signal.SIGKILL, "the study finished before two kills"
        in_db = {r[0] for r in _raw(url, "SELECT trial_index FROM trials WHERE participant = 'K1'")}
        assert reported <= in_db, f"reported saved but missing: {sorted(reported - in_db)}"
        assert sorted(in_db) == list(range(len(in_db)))
    finished = subprocess.run(_cmd(design, url, 0.0), capture_output=True, text=True, env=env, timeout=120)
    assert finished.returncode == 0, finished.stderr
    assert _answers(url) == _answers(reference) and len(_answers(url)) == 9 * 9
    assert _raw(url, "SELECT COUNT(*) FROM sessions")[0][0] == 3
    pd.testing.assert_frame_equal(_export_without_timing(url), _export_without_timing(reference))

    csv = tmp_path / "pg.csv"
    out = subprocess.run([*CLI, "export", url, "--csv", str(csv)], capture_output=True, text=True, env=env,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    from results_analysis.loader import load_results

    from studyapp.study.export import export_dataframe

    ref_csv = tmp_path / "ref.csv"
    export_dataframe(reference).to_csv(ref_csv, index=False)  # what `studyapp export --csv` writes
    drop = ["response_time_s", "session"]
    pd.testing.assert_frame_equal(load_results(csv).drop(columns=drop), load_results(ref_csv).drop(columns=drop))


def test_merge_imports_a_results_file_into_either_backend_once(results_target: Path | str, tmp_path: Path) -> None:
    """A participant's results file (a session on another machine's SQLite file) merged into a database on each
    backend: every answer arrives as recorded, checked against the schedule first; merged again, nothing to do."""
    from studyapp.bots.session_driver import run_bot_session
    from studyapp.study.bundle import merge_results, write_results_file
    from studyapp.study.design import load_design

    design_path = write_synthetic_study(tmp_path / "study", n_stimuli=3, seconds=0.3)
    design = load_design(design_path)
    with ResultsDB(tmp_path / "elsewhere.sqlite", design) as away:
        run_bot_session(design, away, "P7", "ordered", 3, pace_s=0.3)  # watched as long as each clip lasts
        results_file = write_results_file(away, "P7", tmp_path / "returned")
    open_results(results_target, design).close()
    [first] = merge_results(results_target, [results_file], design=design_path)
    assert first.ok and not first.already and first.participant == "P7", first.problems
    [again] = merge_results(results_target, [results_file], design=design_path)
    assert again.ok and again.already
    assert _raw(results_target, "SELECT COUNT(*) FROM trials WHERE participant = 'P7'")[0][0] == 4
    # (row order aside: a merged file's ranks arrive sorted by criterion, on either backend, so the export lists
    # criteria alphabetically instead of in the order they were asked: an existing behaviour of merge)
    def table(target: Path | str) -> pd.DataFrame:
        df = _export_without_timing(target)
        return df.sort_values(["participant", "trial_index", "criterion", "slot"]).reset_index(drop=True)

    pd.testing.assert_frame_equal(table(results_target), table(tmp_path / "elsewhere.sqlite"), check_exact=True)


def test_a_dropped_server_connection_is_made_again_between_answers(postgres_server) -> None:
    """The database server drops the study's connection (a restart, a network cut): the next answer is stored
    on a new connection; an answer whose transaction was cut short is reported not saved, never half stored."""
    url = postgres_server.new_database("dropped")
    db = open_results(url, design_hash="ff" * 20, title="Dropped")
    db.add_participant("P1", n_rows=1)
    s = db.start_session("P1")

    def drop() -> None:
        _raw(url, "SELECT pg_terminate_backend(pid) FROM pg_stat_activity WHERE datname = 'dropped' "
                  "AND pid <> pg_backend_pid()")

    drop()
    db.save_trial(*_trial("P1", 0, s))  # a new connection, the answer stored
    drop()
    assert db.answered_trials("P1") == {0}
    rec, ranks = _trial("P1", 1, s)
    with db.transaction() as con:
        con.execute("SELECT 1")
    real_insert = db._insert

    def cut(con, table, rows):  # the connection dies between the trial row and its ranks
        ids = real_insert(con, table, rows)
        if table == "trials":
            drop()
        return ids

    db._insert = cut  # type: ignore[method-assign]
    with pytest.raises(InputError, match="cannot reach the PostgreSQL server .*was not saved"):
        db.save_trial(rec, ranks)
    db._insert = real_insert  # type: ignore[method-assign]
    assert db.answered_trials("P1") == {0}  # nothing of the cut answer, and the connection works again
    db.save_trial(rec, ranks)
    db.close()
    assert _raw(url, "SELECT trial_index, COUNT(*) FROM responses GROUP BY trial_index ORDER BY 1") == [(0, 3), (1, 3)]


def test_missing_postgresql_binaries_fail_with_what_to_install(tmp_path: Path, monkeypatch) -> None:
    """Without Debian's postgresql package the PostgreSQL tests fail (the fixture raises this), never skip."""
    from fixtures.postgres import PostgresMissing, find_bin

    monkeypatch.delenv("STUDYAPP_PG_BIN", raising=False)
    with pytest.raises(PostgresMissing, match=r"apt-get install postgresql"):
        find_bin(lib_root=tmp_path, search_path=str(tmp_path))
    (tmp_path / "15" / "bin").mkdir(parents=True)
    for tool in ("initdb", "pg_ctl"):
        (tmp_path / "15" / "bin" / tool).write_text("")
    assert find_bin(lib_root=tmp_path, search_path=str(tmp_path)) == tmp_path / "15" / "bin"


@pytest.mark.parametrize("paradigm", ["pairwise", "mismatch", "rating"])
def test_paradigm_answers_export_the_same_from_postgresql(paradigm: str, tmp_path: Path, postgres_server) -> None:
    """Each paradigm example answered through the Session with the same seeds into an SQLite file and a
    PostgreSQL database: the tidy export (judgements, trial slots, blocks) is the same from both."""
    import test_paradigms  # the same folder: the examples and the scripted answers of the paradigm tests
    from studyapp.study.design import load_design

    design = load_design(test_paradigms.EXAMPLES[paradigm], check_files=False)
    url = postgres_server.new_database(f"paradigm_{paradigm}")
    for target in (tmp_path / "r.sqlite", url):
        with ResultsDB(target, design) as db:
            for k in range(2):
                test_paradigms._run(design, db, f"P{k}", k)
    sqlite_table, pg_table = _export_without_timing(tmp_path / "r.sqlite"), _export_without_timing(url)
    assert len(pg_table) > 0 and set(pg_table["paradigm"]) == {paradigm} | ({"rank"} & set(sqlite_table["paradigm"]))
    pd.testing.assert_frame_equal(pg_table, sqlite_table, check_exact=True)


def test_criterion_labels_and_the_upgrade_from_schema_6_on_both_backends(results_target: Path | str) -> None:
    """Schema 7 on either engine: a version 6 database (no table criteria) is upgraded in place; opened with its
    design it records each criterion's label and question, and the export carries the labels."""
    from types import SimpleNamespace as NS

    from studyapp.study.export import export_dataframe

    db = open_results(results_target, design_hash="ef56", title="T")
    db.add_participant("P1", n_rows=2)
    db.save_trial(*_trial("P1", 0, db.start_session("P1")))
    db.close()
    _raw(results_target, "DROP TABLE criteria")  # what studyapp wrote before schema 7, its rows sealed as then
    _raw(results_target, "UPDATE schema_version SET version = 6")
    backend = sql_backend.backend_for(results_target)
    con = backend.connect(30.0)
    backend.begin_write(con)
    row_checksums.seal_all(con)
    con.execute("COMMIT")
    con.close()
    assert export_dataframe(results_target)["criterion_label"].tolist() == ["realism"] * 3  # the id: no label
    design = NS(design_hash="ef56", title="T", criteria=[
        NS(id="realism", label="Looks like a real person", question="Which looks real?")])
    with open_results(results_target, design) as db:
        assert db.connection.execute("SELECT version FROM schema_version").fetchone()[0] == 7
        assert db.criteria() == [{"id": "realism", "position": 0, "label": "Looks like a real person",
                                  "question": "Which looks real?"}]
    assert _raw(results_target, "SELECT label FROM criteria") == [("Looks like a real person",)]
    assert export_dataframe(results_target)["criterion_label"].tolist() == ["Looks like a real person"] * 3
    open_results(results_target, create=False).close()  # every row, the new ones too, matches its checksum
