"""Group commit (:meth:`ResultsDB.batch`, :class:`studyapp.web.dbthread.DatabaseThread`): requests that queue up
are committed together, each answered only once it is on disk; one request's failure undoes only its own
change; a failed commit fails every request of the group."""
from __future__ import annotations

import sqlite3
import threading
from contextlib import contextmanager
from typing import Iterator

import pytest

from studyapp.errors import InputError
from studyapp.study.storage import ResultsDB
from studyapp.web.dbthread import DatabaseThread


def stored(path, table: str = "participants") -> list[str]:
    """What another connection sees: only committed rows."""
    con = sqlite3.connect(path)
    try:
        return [r[0] for r in con.execute(f"SELECT {'id' if table == 'participants' else 'participant'} FROM {table} "
                                          "ORDER BY 1")]
    finally:
        con.close()


def test_a_batch_commits_once_and_undoes_a_failed_transaction_alone(tmp_path) -> None:
    path = tmp_path / "r.sqlite"
    db = ResultsDB(path, design_hash="h", title="t")
    with db.batch():
        db.add_participant("P1", n_rows=2)
        with pytest.raises(Exception):
            with db.transaction() as con:
                con.execute("INSERT INTO participants (id, latin_row, groups, status, created, design_hash, "
                            "app_version) VALUES ('P2', 0, '{}', 'active', 'x', 'h', 'v')")
                raise RuntimeError("the request failed after writing")
        db.add_participant("P3", n_rows=2)
        assert stored(path) == []            # nothing is on disk before the batch's commit
    assert stored(path) == ["P1", "P3"]
    db.close()
    reopened = ResultsDB(path, create=False)   # every row of the batch carries its checksum
    assert [p.id for p in reopened.participants()] == ["P1", "P3"]
    reopened.close()


def test_queued_requests_are_answered_only_once_all_of_them_are_on_disk(tmp_path) -> None:
    path = tmp_path / "r.sqlite"
    thread = DatabaseThread()
    db = thread.submit(lambda: ResultsDB(path, design_hash="h", title="t")).result()
    thread.group_commit(db)
    gate = threading.Event()
    first = hold(thread, gate)
    seen_when_answered: dict[str, list[str]] = {}

    def add(pid: str):
        return lambda: db.add_participant(pid, n_rows=2).id

    futures = {pid: thread.submit(add(pid)) for pid in ("A", "B", "C")}
    failing = thread.submit(lambda: db.add_participant("A", n_rows=2))   # a duplicate: refused, alone
    for pid, fut in futures.items():
        fut.add_done_callback(lambda f, pid=pid: seen_when_answered.setdefault(pid, stored(path)))
    gate.set()
    assert first.result(30) is True
    assert [f.result(30) for f in futures.values()] == ["A", "B", "C"]
    with pytest.raises(Exception, match="already"):
        failing.result(30)
    # each was answered when every one of the group was committed: none before its own row was on disk
    assert all(seen == ["A", "B", "C"] for seen in seen_when_answered.values()), seen_when_answered
    thread.submit(db.close).result(30)
    thread.close()


def hold(thread: DatabaseThread, gate: threading.Event):
    """A job that holds the thread until ``gate`` opens, running (so alone) when this returns."""
    running = threading.Event()
    fut = thread.submit(lambda: running.set() or gate.wait(30))
    assert running.wait(30)
    return fut


class FailingCommit:
    """A database whose group commit fails (a full disk at COMMIT)."""

    def __init__(self) -> None:
        self.ran: list[str] = []

    @contextmanager
    def batch(self) -> Iterator[None]:
        yield
        raise InputError("results.sqlite", None, "the disk is full; nothing was saved")


def test_a_failed_commit_fails_every_request_of_the_group() -> None:
    thread = DatabaseThread()
    fake = FailingCommit()
    thread.group_commit(fake)
    gate = threading.Event()
    first = hold(thread, gate)
    queued = [thread.submit(lambda k=k: fake.ran.append(f"job{k}") or k) for k in range(3)]
    gate.set()
    first.result(30)
    for fut in queued:
        with pytest.raises(InputError, match="disk is full"):
            fut.result(30)
    assert fake.ran == ["job0", "job1", "job2"]   # they ran, and none of them is reported stored
    thread.close()
