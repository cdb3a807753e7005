"""Writers side by side on one results database (storage.py, sql_backend.py's ``begin_write``), checked against the
database itself (raw sqlite3/psycopg reads) and its row checksums.

On PostgreSQL a write of one participant's rows holds that participant's lock and the database's write lock
shared: answers of different participants commit side by side, while a second write of the same participant and
a write across participants (a new participant on the least-used Latin-square row) wait for it. On both backends,
many participants answering at once from many connections leave every answer stored exactly once (a double
submit is refused as a duplicate, never stored twice), every read-modify-write of a session record complete,
the Latin-square rows balanced and every row matching its checksum.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from concurrent.futures import Future
from pathlib import Path
from typing import Callable

import pytest

from studyapp.study import row_checksums
from studyapp.study.storage import DuplicateAnswerError, Response, TrialRecord, now_iso, open_results

HASH = "cc" * 20
CLI = [sys.executable, "-m", "studyapp.cli"]


def _trial(pid: str, index: int, session: int) -> tuple[TrialRecord, list[Response]]:
    rec = TrialRecord(pid, index, f"clip{index:02d}", False, False, ("a", "b", "c"), now_iso(), session=session)
    return rec, [Response(crit, c, s, r) for crit in ("realism", "sync")
                 for s, (c, r) in enumerate(zip("abc", (2.0, 1.0, 3.0)))]


def _raw(target: Path | str, sql: str) -> list[tuple]:
    if isinstance(target, Path):
        import sqlite3

        con = sqlite3.connect(target, isolation_level=None)
        try:
            return con.execute(sql).fetchall()
        finally:
            con.close()
    import psycopg

    with psycopg.connect(target, autocommit=True) as con:
        return con.execute(sql).fetchall()


def _in_thread(fn: Callable[[], object]) -> Future:
    fut: Future = Future()

    def run() -> None:
        try:
            fut.set_result(fn())
        except BaseException as exc:  # the test reads it
            fut.set_exception(exc)
    threading.Thread(target=run, daemon=True).start()
    return fut


def _wait_for(con: object, n: int, query: str = "", timeout_s: float = 60.0) -> None:
    """Until ``n`` server connections wait on a lock (those running a statement that starts with ``query``);
    ``con`` outside a transaction (inside one, the server shows the activity as it was at its start)."""
    give_up = time.monotonic() + timeout_s
    while con.execute("SELECT COUNT(*) FROM pg_stat_activity WHERE wait_event_type = 'Lock' AND "  # type: ignore
                      "query LIKE %s", (query + "%",)).fetchone()[0] < n:
        assert time.monotonic() < give_up, f"fewer than {n} connections waited on a lock"
        time.sleep(0.05)


def test_other_participants_answers_commit_while_one_participants_write_waits(postgres_server) -> None:
    """Participant A's answer is held up inside its transaction (the test locks A's participants row, which the
    answer's foreign key must share): B's answer commits meanwhile; A's next answer and a new participant (a
    Latin-square row chosen from every participant's count) wait until A's commits, then go through. With one
    database-wide write lock for every write, B's answer would wait for A's."""
    import psycopg

    url = postgres_server.new_database("side_by_side")
    setup = open_results(url, design_hash=HASH, title="Side by side")
    setup.add_participant("A", n_rows=2)
    setup.add_participant("B", n_rows=2)
    sa, sb = setup.start_session("A"), setup.start_session("B")
    setup.close()
    dbs = [open_results(url, create=False) for _ in range(4)]
    blocker, watcher = psycopg.connect(url, autocommit=True), psycopg.connect(url, autocommit=True)
    try:
        blocker.execute("BEGIN")
        blocker.execute("SELECT 1 FROM participants WHERE id = 'A' FOR UPDATE")
        a0 = _in_thread(lambda: dbs[0].save_trial(*_trial("A", 0, sa)))
        _wait_for(watcher, 1, "INSERT INTO trials")   # A's answer is in its transaction, waiting for the row
        b0 = _in_thread(lambda: dbs[1].save_trial(*_trial("B", 0, sb)))
        b0.result(timeout=20)                      # B's answer committed while A's waits
        assert not a0.done()
        assert _raw(url, "SELECT participant FROM trials") == [("B",)]
        a1 = _in_thread(lambda: dbs[2].save_trial(*_trial("A", 1, sa)))
        c = _in_thread(lambda: dbs[3].add_participant("C", n_rows=2))
        _wait_for(watcher, 3)                          # both wait on a lock
        assert not a1.done() and not c.done()      # A's next answer and the new participant wait for A's first
        blocker.execute("ROLLBACK")
        a0.result(timeout=20)
        a1.result(timeout=20)
        assert c.result(timeout=20).latin_row == 0  # A and B hold rows 0 and 1
    finally:
        blocker.close()   # lets every waiting write go on (a failed test: before closing their connections)
        watcher.close()
        for fut in locals().get("a0"), locals().get("a1"), locals().get("b0"), locals().get("c"):
            if fut is not None:
                try:
                    fut.result(timeout=60)
                except BaseException:
                    pass
        for db in dbs:
            db.close()
    assert sorted(_raw(url, "SELECT participant, trial_index FROM trials")) == [("A", 0), ("A", 1), ("B", 0)]
    with open_results(url, create=False) as db:    # opening checks every row against its checksum
        assert row_checksums.verify(db.connection) == []


@pytest.mark.timeout(300)
def test_many_participants_answering_at_once_store_every_answer_exactly_once(results_target: Path | str) -> None:
    """12 connections, 24 participants registered and answering at once (every answer submitted twice, from two
    connections at the same moment; plays and session records written alongside): every trial stored exactly
    once with all its ranks, each double submit refused once as a duplicate, no session record update lost, the
    Latin-square rows balanced and every row matching its checksum."""
    n_conn, per_conn, n_trials = 12, 2, 5
    open_results(results_target, design_hash=HASH, title="Crowd").close()
    start, registered = threading.Barrier(n_conn), threading.Barrier(n_conn)
    duplicates: list[int] = []
    errors: list[BaseException] = []
    sessions: dict[str, int] = {}

    def participant_ids(k: int) -> list[str]:
        return [f"P{k:02d}-{j}" for j in range(per_conn)]

    def worker(k: int) -> None:
        # connection k answers for its own participants and for those of connection k - 1, in the same order:
        # every answer is submitted twice, from two connections, about at once (a double submit from two tabs)
        db = open_results(results_target, create=False)   # its own connection (SQLite's belong to a thread)
        try:
            start.wait(timeout=60)
            for pid in participant_ids(k):
                db.add_participant(pid, n_rows=4)
                sessions[pid] = db.start_session(pid, {"frontend": "test"})
            registered.wait(timeout=120)
            both = participant_ids(k) + participant_ids((k - 1) % n_conn)
            for i in range(n_trials):
                for pid in both:
                    play = db.start_play(pid, i, sessions[pid])
                    db.finish_play(play, True)
                    db.update_session_machine(sessions[pid], {f"seen_by_{k}_{i}": True})
                    try:
                        db.save_trial(*_trial(pid, i, sessions[pid]))
                    except DuplicateAnswerError:
                        duplicates.append(1)
            for pid in participant_ids(k):
                db.set_status(pid, "done")
        except BaseException as exc:  # reported by the main thread
            errors.append(exc)
            start.abort()
            registered.abort()
        finally:
            db.close()

    threads = [threading.Thread(target=worker, args=(k,)) for k in range(n_conn)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=240)
    assert not errors, errors
    n_participants = n_conn * per_conn
    assert len(duplicates) == n_participants * n_trials       # one of each pair of submits refused
    rows = _raw(results_target, "SELECT participant, trial_index, COUNT(*) FROM trials GROUP BY participant, "
                "trial_index HAVING COUNT(*) <> 1")
    assert rows == []
    assert _raw(results_target, "SELECT COUNT(*) FROM trials")[0][0] == n_participants * n_trials
    assert _raw(results_target, "SELECT COUNT(*) FROM responses")[0][0] == n_participants * n_trials * 6
    assert _raw(results_target, "SELECT COUNT(*) FROM plays WHERE completed = 1")[0][0] == \
        2 * n_participants * n_trials
    assert _raw(results_target, "SELECT latin_row, COUNT(*) FROM participants GROUP BY latin_row ORDER BY 1") == \
        [(r, n_participants // 4) for r in range(4)]
    with open_results(results_target, create=False) as db:   # every row checked against its checksum
        assert row_checksums.verify(db.connection) == []
        for pid, sid in sessions.items():
            k = int(pid[1:3])
            machine = next(s for s in db.sessions(pid) if s["id"] == sid)["machine"]
            # both connections that answered for this participant merged their keys: none lost to the other
            want = {f"seen_by_{w}_{i}" for w in (k, (k + 1) % n_conn) for i in range(n_trials)}
            assert want <= set(machine), sorted(want - set(machine))
        assert all(p.status == "done" for p in db.participants())


@pytest.mark.timeout(300)
@pytest.mark.skipif(os.name != "posix", reason="SIGKILL is POSIX")
def test_participants_in_processes_of_their_own_one_killed_lose_no_answer(tmp_path: Path, postgres_server) -> None:
    """Four `studyapp run` processes, four participants, one PostgreSQL database, answering at once; one process
    is SIGKILLed right after it reported its second answer saved, and run again to the end: every answer a
    process reported saved is stored, every participant's answers are those of an uninterrupted SQLite run
    with the same seed (each trial once, all its ranks), and every row matches its checksum."""
    from studyapp.bots import run_bot
    from studyapp.study.design import load_design
    from studyapp.study.session import prepare_participant
    from fixtures.synthetic import write_synthetic_study

    design = write_synthetic_study(tmp_path / "study", n_stimuli=8, seconds=0.5, questionnaire=True)
    loaded = load_design(design)
    url = postgres_server.new_database("processes")
    pids = [f"K{k}" for k in range(4)]
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}

    def run(pid: str, pace: float) -> subprocess.Popen:
        return subprocess.Popen([*CLI, "run", str(design), "--participant", pid, "--results", url, "--no-render",
                                 "--bot", "random", "--seed", "5", "--bot-pace", str(pace)], stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True, env=env)

    procs = {pid: run(pid, 0.05 if pid == "K0" else 0.01) for pid in pids}
    reported: dict[str, set[int]] = {pid: set() for pid in pids}
    for line in procs["K0"].stdout:   # type: ignore[union-attr]
        if line.startswith("saved trial"):
            reported["K0"].add(int(line.split()[-1]))
            if len(reported["K0"]) == 2:
                os.kill(procs["K0"].pid, signal.SIGKILL)
                break
    procs["K0"].wait(timeout=30)
    assert procs["K0"].returncode == -signal.SIGKILL, "K0 finished before it was killed"
    for pid in pids[1:]:
        out, err = procs[pid].communicate(timeout=240)
        assert procs[pid].returncode == 0, err[-2000:]
        reported[pid] = {int(ln.split()[-1]) for ln in out.splitlines() if ln.startswith("saved trial")}
    stored = {pid: {r[0] for r in _raw(url, f"SELECT trial_index FROM trials WHERE participant = '{pid}'")}
              for pid in pids}
    assert reported["K0"] <= stored["K0"], "an answer reported saved was lost"
    again = subprocess.run([*CLI, "run", str(design), "--participant", "K0", "--results", url, "--no-render", "--bot",
                            "random", "--seed", "5"], capture_output=True, text=True, env=env, timeout=240)
    assert again.returncode == 0, again.stderr[-2000:]

    answers = ("SELECT r.participant, r.trial_index, r.criterion, r.slot, r.condition, r.rank FROM responses r "
               "ORDER BY 1, 2, 3, 4")
    rows = dict(_raw(url, "SELECT id, latin_row FROM participants"))
    assert sorted(rows.values()) == [0, 1, 2, 3]   # registered at once, each on a row of their own
    reference = tmp_path / "reference.sqlite"     # each participant alone, on the row they got
    with open_results(reference, loaded) as ref:
        for pid in pids:
            prepare_participant(loaded, ref, pid, row=rows[pid])
            assert run_bot(loaded, ref, pid, "random", 5, render=False) == 0
    assert _raw(url, answers) == _raw(reference, answers) and len(_raw(url, answers)) == 4 * 9 * 9
    assert _raw(url, "SELECT COUNT(*) FROM trials")[0][0] == 4 * 9
    with open_results(url, create=False) as db:   # every row checked against its checksum
        assert row_checksums.verify(db.connection) == []
