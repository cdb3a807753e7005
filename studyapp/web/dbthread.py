"""The one thread of a server process that does all its database work, so the event loop never waits on it.

Every request's database work (restoring a session, the action, the commit) is a job run here, one job at a
time in arrival order: on SQLite, whose connection belongs to one thread, this is what keeps two requests of
one participant from interleaving. While a job waits on the disk (a commit's fsync) or on the database server,
the event loop goes on reading requests, writing replies and sending videos to every other participant. On
PostgreSQL a process has :data:`PG_THREADS` such threads, each with its own connection (a request's dozen
statements are round trips to the server: several requests wait on them side by side); the per-participant lock
that keeps one participant's requests apart across processes keeps them apart across threads too.

Group commit (:meth:`DatabaseThread.group_commit`): jobs that queued up while one ran are run together in one
write transaction, every transaction of theirs a savepoint of it, committed (one fsync) before any of them is
answered (:meth:`~studyapp.study.storage.ResultsDB.batch`): a job's failed transaction is undone alone, as it
would be on its own; a failed commit fails every job of the batch (nothing of them is stored; each participant
is told so). So every answer is still on disk before the page after it is sent, at one fsync per batch instead of one per request. Only for
SQLite (one server process): on PostgreSQL a batch would hold the database's write lock while waiting for a
participant's lock another process holds.
"""
from __future__ import annotations

import asyncio
import logging
import queue
import threading
from concurrent.futures import Future
from contextlib import AbstractContextManager
from typing import Any, Callable, Protocol, TypeVar

_log = logging.getLogger(__name__)
T = TypeVar("T")
#: The most jobs committed together (a bound on how long the first one waits for the others).
MAX_BATCH = 64
#: Database threads (connections) of one server process on PostgreSQL; ``--workers N`` makes N times as many.
PG_THREADS = 4


class Batching(Protocol):
    """What group commit needs of the database (:class:`~studyapp.study.storage.ResultsDB`)."""

    def batch(self) -> AbstractContextManager[Any]: ...


class DatabaseThread:
    """Runs jobs (plain functions) on one thread, with group commit on ``batching`` (see the module notes)."""

    def __init__(self, name: str = "studyapp-db") -> None:
        self._jobs: queue.SimpleQueue[tuple[Callable[[], Any], Future] | None] = queue.SimpleQueue()
        self._batching: Batching | None = None
        self._name = name
        self._threads: list[threading.Thread] = []
        self._start(None, None)

    def add_threads(self, n: int, setup: Callable[[], None], teardown: Callable[[], None]) -> None:
        """``n`` more threads taking jobs from the same queue, each running ``setup`` first (opening its own
        connection) and ``teardown`` when it stops. For PostgreSQL, whose connections work side by side; one
        participant's requests still run one at a time (the flow's per-participant lock)."""
        if self._batching is not None:
            raise RuntimeError("group commit needs the one thread")
        for _ in range(n):
            self._start(setup, teardown)

    def _start(self, setup: Callable[[], None] | None, teardown: Callable[[], None] | None) -> None:
        thread = threading.Thread(target=self._loop, args=(setup, teardown), daemon=True,
                                  name=f"{self._name}-{len(self._threads)}")
        self._threads.append(thread)
        thread.start()

    def group_commit(self, db: Batching | None) -> None:
        """Commit the jobs that queue up together on ``db`` from now on (None: each job commits its own)."""
        if db is not None and len(self._threads) > 1:
            raise RuntimeError("group commit needs the one thread")
        self._batching = db

    def submit(self, fn: Callable[[], T]) -> "Future[T]":
        fut: Future = Future()
        self._jobs.put((fn, fut))
        return fut

    async def run(self, fn: Callable[..., T], *args: Any) -> T:
        """``fn(*args)`` on the database thread, awaited."""
        return await asyncio.wrap_future(self.submit(lambda: fn(*args)))

    def close(self) -> None:
        """Run the jobs already queued, then stop the threads."""
        for _ in self._threads:
            self._jobs.put(None)
        for thread in self._threads:
            thread.join()

    def _loop(self, setup: Callable[[], None] | None, teardown: Callable[[], None] | None) -> None:
        if setup is not None:
            try:
                setup()
            except Exception:   # no connection for this thread: the others serve
                _log.exception("a database thread could not start")
                return
        try:
            self._serve()
        finally:
            if teardown is not None:
                teardown()

    def _serve(self) -> None:
        while True:
            job = self._jobs.get()
            if job is None:
                return
            jobs = [job]
            batching = self._batching
            while batching is not None and len(jobs) < MAX_BATCH:
                try:
                    nxt = self._jobs.get_nowait()
                except queue.Empty:
                    break
                if nxt is None:
                    self._jobs.put(None)   # stop after this batch
                    break
                jobs.append(nxt)
            if batching is None or len(jobs) == 1:
                for fn, fut in jobs:
                    _settle(fut, fn)
                continue
            self._run_batch(batching, jobs)

    @staticmethod
    def _run_batch(db: Batching, jobs: list[tuple[Callable[[], Any], Future]]) -> None:
        done: list[tuple[Future, bool, Any]] = []
        try:
            with db.batch():
                for fn, fut in jobs:
                    if not fut.set_running_or_notify_cancel():
                        continue   # its request is gone
                    try:
                        done.append((fut, True, fn()))
                    except BaseException as exc:   # its failed transaction was undone; the others' stand
                        done.append((fut, False, exc))
        except BaseException as exc:              # the commit failed: nothing of the batch is stored
            for _, fut in jobs:
                if fut.running() or (not fut.done() and fut.set_running_or_notify_cancel()):
                    fut.set_exception(exc)
            return
        for fut, ok, value in done:               # answered only now that all of it is on disk
            if ok:
                fut.set_result(value)
            else:
                fut.set_exception(value)


def _settle(fut: Future, fn: Callable[[], Any]) -> None:
    if not fut.set_running_or_notify_cancel():
        return
    try:
        fut.set_result(fn())
    except BaseException as exc:
        fut.set_exception(exc)
