"""Where a results database lives: an SQLite file (the default) or a PostgreSQL database (many server processes).

:class:`~studyapp.study.storage.ResultsDB` owns every result row and writes the same SQL on both; this module
holds only what differs between the two engines, behind one :class:`Backend` seam:

- ``connect``: SQLite opens the file in autocommit mode (``isolation_level=None``, rows as
  :class:`sqlite3.Row`); PostgreSQL opens a psycopg 3 connection in autocommit mode with
  ``synchronous_commit = on`` (a commit returns only once the server's WAL is on disk) and ``lock_timeout``
  set to the same wait as SQLite's busy timeout. A connection the server dropped is made again at the next
  statement outside a transaction (a study server outlives a database restart); a transaction cut short is
  reported as not saved, never repeated.
- ``begin_write``: SQLite's ``BEGIN IMMEDIATE`` takes the database's write lock up front: every write runs
  alone. PostgreSQL's equivalent is ``BEGIN`` followed by transaction-scoped advisory locks, in one of two
  scopes (storage.py says which each write is):

  - the whole database (``participant=None``): :data:`WRITE_LOCK_KEY` held exclusively. Such a write runs
    alone among every writer of every server process, exactly as on SQLite, so each check-then-write that
    reads other participants' rows or the study's (the least-used Latin-square row, "already merged",
    "already upgraded", the tables made once) reads what every earlier commit wrote and can never be raced;
  - one participant's rows (``participant=KEY``): first that participant's lock (``PARTICIPANT_LOCK_SPACE``,
    KEY: the key :meth:`hold` takes for a whole request, so within a request it is already held), then
    :data:`WRITE_LOCK_KEY` *shared*. Writes of different participants commit side by side; two of one
    participant run one at a time (so "already answered" and a read-modify-write of their session record
    read every earlier commit of theirs); and none runs while a whole-database write does, so that one still
    sees no write in flight. Their rows are their own (keys start with the participant), so row locks and
    the primary keys keep them apart; row ids come from identity sequences, which never wait.

  Every transaction takes its locks in that order (a participant's, then the database's) before its first
  row lock, and no transaction holding the database's lock waits for a participant's, so the locks cannot
  deadlock. PostgreSQL queues a shared request behind a waiting exclusive one: a whole-database write (a new
  participant) waits only for the answers already in flight. Readers never wait. Each write is a few
  statements, so the locks are held for milliseconds.
- ``kind`` / ``problem``: an engine error sorted into full, readonly, busy, io, unreachable, damaged or
  other, and the one-line :class:`~studyapp.errors.InputError` that says what to do.
- the SQL dialect: storage.py, :mod:`studyapp.study.row_checksums` and
  :func:`results_analysis.sqlite_schema.tidy_table` write SQLite's SQL; on PostgreSQL
  :class:`PgConnection` runs it through :func:`translate` (one cached rewrite per statement text):
  ``?`` placeholders become ``%s``; ``INSERT OR IGNORE`` becomes ``ON CONFLICT DO NOTHING`` and
  ``INSERT OR REPLACE`` an upsert on the table's primary key; ``sqlite_master`` is answered from
  ``information_schema`` and ``PRAGMA table_info(T)`` from the catalog; ``CAST(x AS BLOB)`` reads the
  UTF-8 bytes; ``CREATE TABLE`` maps ``INTEGER`` to ``BIGINT`` (SQLite's integers are 64-bit),
  ``REAL`` to ``DOUBLE PRECISION`` (PostgreSQL's ``REAL`` is 32-bit), ``INTEGER PRIMARY KEY
  AUTOINCREMENT`` to an identity column, drops ``WITHOUT ROWID``, and gives every table a ``rowid``
  column (its integer primary key where it has one, as in SQLite, else an identity): row checksums,
  ``lastrowid`` and the tidy query's ``rowid`` then mean the same on both. ``SELECT *`` leaves ``rowid``
  out, as SQLite does. A plain ``BEGIN`` (a read transaction) is ``REPEATABLE READ``: one snapshot, so
  checking every row against its checksum never sees half of another server's commit.
- row checksums: SQLite records the rows a transaction changed with temporary triggers; PostgreSQL with
  one permanent row trigger per table (created with the table) into ``_studyapp_dirty_rows``, keyed by the
  writing transaction's id, so rows written by another program (``psql``) stay unsealed and are reported.

A target names the backend (:func:`backend_for`): ``postgresql://...`` or ``postgres://...`` is PostgreSQL
(a libpq URL; the password is never shown in a message), ``sqlite:///path`` or any other text a file path.
"""
from __future__ import annotations

import errno
import re
import shutil
import sqlite3
from functools import lru_cache
from pathlib import Path
from typing import Any, Iterator, Protocol, Sequence
from urllib.parse import urlsplit, urlunsplit

from studyapp.errors import InputError

_SQLITE_MAGIC = b"SQLite format 3\x00"
#: Free space under which an I/O error while writing is taken for a full disk.
_NEARLY_FULL_BYTES = 1 << 20
#: The advisory lock every PostgreSQL write transaction takes (per database; any fixed 64-bit number).
WRITE_LOCK_KEY = 0x5374756479617070  # "Studyapp"
#: The first key of the advisory locks that run one participant's requests one at a time (:meth:`hold`).
PARTICIPANT_LOCK_SPACE = 0x53747564  # "Stud"
#: Where PostgreSQL records the rows a transaction changed (see :mod:`studyapp.study.row_checksums`).
PG_DIRTY_TABLE = "_studyapp_dirty_rows"
_PG_DIRTY_FUNC = "_studyapp_mark_dirty"


class Cursor(Protocol):
    """What storage reads from a statement: rows (by index and by column name), and the new row's id."""

    lastrowid: int | None
    description: Any

    def fetchone(self) -> Any: ...
    def fetchall(self) -> list[Any]: ...
    def __iter__(self) -> Iterator[Any]: ...


class Connection(Protocol):
    """The part of :class:`sqlite3.Connection` storage uses; :class:`PgConnection` offers the same."""

    def execute(self, sql: str, parameters: Sequence[Any] = ...) -> Cursor: ...
    def executemany(self, sql: str, seq_of_parameters: Any) -> Cursor: ...
    def close(self) -> None: ...
    @property
    def in_transaction(self) -> bool: ...


class Backend(Protocol):
    """Everything that differs between the engines a results database can live in."""

    #: "sqlite" or "postgresql"
    name: str
    #: What messages name: the file (a Path), or the URL without its password (a str).
    target: Path | str
    #: The engine's exception classes (caught and turned into one-line messages).
    errors: tuple[type[Exception], ...]

    def exists(self) -> bool:
        """Whether there is a database to open (SQLite: a non-empty file; PostgreSQL: always, the server's)."""
    def check_before_open(self, exists: bool, writing: bool) -> None:
        """Checks made before connecting (SQLite: the file header, write access; makes the folder)."""
    def connect(self, lock_timeout_s: float) -> Connection: ...
    def configure(self, con: Connection) -> None:
        """Per-connection settings that make every commit durable (SQLite: WAL, synchronous=FULL)."""
    def integrity_check(self, con: Connection) -> list[str]:
        """The engine's own structural check: ``["ok"]`` or one entry per problem."""
    def begin_write(self, con: Connection, participant: int | None = None) -> None:
        """Start a write transaction that runs alone among this database's writers (``participant`` None), or
        (``participant``: the key of :meth:`hold`) one that writes only that participant's rows: alone among
        that participant's writes and the whole-database ones, beside other participants' (see the module
        docstring; SQLite runs every write alone)."""
    def hold(self, con: Connection, key: int, held: bool) -> None:
        """Take (``held``) or give back lock ``key`` (a signed 32-bit number) across transactions, for one
        participant's requests in several server processes; SQLite serves one process and needs none."""
    def kind(self, exc: BaseException) -> str:
        """full, readonly, busy, io, unreachable, damaged or other."""
    def problem(self, exc: BaseException, what: str) -> InputError:
        """The one-line message for an engine error; ``what`` says what was (not) done."""


def is_url(target: str | Path) -> bool:
    """Whether ``target`` names a database server (``postgresql://``) rather than a file."""
    return isinstance(target, str) and target.lower().startswith(("postgresql://", "postgres://"))


def results_target(text: str) -> Path | str:
    """A command line's results database: a PostgreSQL URL as it is, a ``sqlite:///`` URL or a path as a Path."""
    if is_url(text):
        return text
    if text.lower().startswith("sqlite:///"):
        return Path(text[len("sqlite:///"):])  # SQLAlchemy's form: sqlite:///relative, sqlite:////absolute
    return Path(text)


def backend_for(target: str | Path) -> Backend:
    """The backend a results target names (see the module docstring)."""
    if is_url(target):
        return PostgresBackend(str(target))
    if isinstance(target, str) and target.lower().startswith("sqlite:///"):
        target = results_target(target)
    return SQLiteBackend(Path(target))


# ====================================================================================================== SQLite
def _kind(exc: BaseException) -> str:
    """What an SQLite error means for the user: full, readonly, busy, io, damaged or other."""
    name = str(getattr(exc, "sqlite_errorname", "") or "")
    text = str(exc).lower()
    if name.startswith("SQLITE_FULL") or "disk is full" in text:
        return "full"
    if name.startswith(("SQLITE_READONLY", "SQLITE_CANTOPEN", "SQLITE_PERM", "SQLITE_AUTH")) or "readonly" in text \
            or "unable to open" in text:
        return "readonly"
    if name.startswith(("SQLITE_BUSY", "SQLITE_LOCKED")) or "locked" in text or "busy" in text:
        return "busy"
    if name.startswith("SQLITE_IOERR") or "disk i/o error" in text:
        return "io"
    if name.startswith(("SQLITE_CORRUPT", "SQLITE_NOTADB")) or isinstance(exc, UnicodeDecodeError) \
            or "malformed" in text or "not a database" in text:
        return "damaged"
    return "other"


def _nearly_full(path: Path) -> bool:
    # SQLite reports some writes on a full disk as I/O errors (e.g. growing the -shm file): ask the disk
    try:
        return shutil.disk_usage(path.parent).free < _NEARLY_FULL_BYTES
    except OSError:
        return False


def sqlite_problem(path: Path, exc: sqlite3.Error | UnicodeDecodeError, what: str) -> InputError:
    """The one-line message for an SQLite error on the results database: a full disk, a read-only file or
    folder, a lock and a failing drive each say so and what to do, kept apart from a damaged file."""
    kind = _kind(exc)
    if kind == "io" and _nearly_full(path):
        kind = "full"
    if kind == "full":
        return InputError(path, None, f"the disk is full ({exc}): {what}. Free some disk space, then start again "
                          "(a session resumes where it stopped)")
    if kind == "readonly":
        return InputError(path, None, f"cannot write the results database or its folder ({exc}): {what}. studyapp "
                          "writes the file and its journal files (-wal, -shm) next to it: make the folder and the "
                          "file writable, or copy the file to a writable folder. Nothing in the file was changed")
    if kind == "busy":
        # Another program holds a lock (a database browser or notebook mid-write): the file is fine, and a
        # new --results file would split the study, so never advise that here.
        return InputError(path, None, f"the results database is in use by another program ({exc}); {what}. "
                          "Close that program (or let it finish) and start again")
    if kind == "io":
        return InputError(path, None, f"the drive reported an error ({exc}): {what}. Check the drive (a removed "
                          "USB stick, a network drive gone away) and start again")
    return InputError(path, None, f"the results database is damaged or not a studyapp database ({exc}); "
                      "keep a copy of the file and start a new one with --results")


def _os_problem(path: Path, exc: OSError) -> InputError:
    if exc.errno in (errno.ENOSPC, errno.EDQUOT):
        return InputError(path, None, f"the disk is full ({exc.strerror}): the results database could not be "
                          "created. Free some disk space, then start again")
    if exc.errno in (errno.EACCES, errno.EPERM, errno.EROFS):
        return InputError(path, None, f"cannot write the results folder ({exc.strerror}): make it writable or "
                          "choose another place with --results")
    return InputError(path, None, f"cannot create or read the results database ({exc.strerror or exc})")


class SQLiteBackend:
    """One SQLite file in WAL mode with ``synchronous=FULL`` (the embedded default)."""

    name = "sqlite"
    errors: tuple[type[Exception], ...] = (sqlite3.Error,)

    def __init__(self, path: Path) -> None:
        self.target: Path = path

    def exists(self) -> bool:
        return self.target.exists() and self.target.stat().st_size > 0

    def check_before_open(self, exists: bool, writing: bool) -> None:
        import os

        if exists and writing and not os.access(self.target, os.W_OK):
            # a session is about to write; say why before the first answer rather than at it
            raise InputError(self.target, None, "the results database is read-only: studyapp cannot save answers "
                             "in it. Make the file (and its folder) writable, or copy it to a writable folder. "
                             "Nothing in the file was changed")
        try:
            if exists:
                with open(self.target, "rb") as fh:
                    head = fh.read(len(_SQLITE_MAGIC))
                if head != _SQLITE_MAGIC:
                    raise InputError(self.target, "file header", "not an SQLite database (wrong file, or damaged); "
                                     "pass a studyapp results file (.sqlite)")
            else:
                self.target.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise _os_problem(self.target, exc) from None

    def connect(self, lock_timeout_s: float) -> Connection:
        try:
            con = sqlite3.connect(str(self.target), isolation_level=None, timeout=lock_timeout_s)
        except sqlite3.Error as exc:
            raise sqlite_problem(self.target, exc, "the results database could not be opened") from None
        con.row_factory = sqlite3.Row
        return con

    def configure(self, con: Connection) -> None:
        from studyapp.study import row_checksums

        mode = con.execute("PRAGMA journal_mode=WAL").fetchone()[0]
        if str(mode).lower() != "wal":
            raise InputError(self.target, None, f"cannot switch the database to WAL journaling (got {mode!r}); "
                             "is it on a read-only or network drive?")
        con.execute("PRAGMA synchronous=FULL")
        con.execute("PRAGMA foreign_keys=ON")
        row_checksums.prepare(con)

    def integrity_check(self, con: Connection) -> list[str]:
        return [str(r[0]) for r in con.execute("PRAGMA integrity_check").fetchall()]

    def begin_write(self, con: Connection, participant: int | None = None) -> None:
        # IMMEDIATE takes the write lock up front, so two processes on one database serialise
        # (e.g. two lab PCs assigning Latin rows) instead of failing half-way.
        con.execute("BEGIN IMMEDIATE")

    def hold(self, con: Connection, key: int, held: bool) -> None:
        pass   # one server process: its database thread already runs a participant's requests one at a time

    def kind(self, exc: BaseException) -> str:
        return _kind(exc)

    def problem(self, exc: BaseException, what: str) -> InputError:
        return sqlite_problem(self.target, exc, what)  # type: ignore[arg-type]


# ================================================================================================== PostgreSQL
def redact(url: str) -> str:
    """The URL without its password (what messages show)."""
    try:
        parts = urlsplit(url)
    except ValueError:
        return "postgresql://…"
    if parts.password is None:
        return url
    netloc = parts.netloc.replace(f":{parts.password}@", ":***@", 1)
    return urlunsplit(parts._replace(netloc=netloc))


class PostgresBackend:
    """A PostgreSQL database (psycopg 3); the database itself must exist, its tables are made on first use."""

    name = "postgresql"

    def __init__(self, url: str) -> None:
        import psycopg

        self.url = url
        self.target: str = redact(url)
        self.errors: tuple[type[Exception], ...] = (psycopg.Error,)

    def exists(self) -> bool:
        return True  # a database without studyapp's tables is a new one (storage creates them)

    def check_before_open(self, exists: bool, writing: bool) -> None:
        pass

    def connect(self, lock_timeout_s: float) -> Connection:
        import psycopg

        def connect() -> Any:
            return psycopg.connect(self.url, autocommit=True, connect_timeout=10)

        try:
            raw = connect()
        except psycopg.Error as exc:
            raise self.problem(exc, "the results database could not be opened") from None
        except Exception as exc:  # a malformed URL (psycopg.ProgrammingError is caught above)
            raise InputError(self.target, None, f"not a usable PostgreSQL URL ({exc}); write it as "
                             "postgresql://USER@HOST:PORT/DATABASE") from None
        return PgConnection(raw, lock_timeout_s, reconnect=connect)

    def configure(self, con: Connection) -> None:
        pass  # PgConnection sets synchronous_commit and lock_timeout when it connects

    def integrity_check(self, con: Connection) -> list[str]:
        # The server checks its own pages (data checksums, when the cluster has them); the rows' contents are
        # checked against their checksums by storage like on SQLite.
        return ["ok"]

    def begin_write(self, con: Connection, participant: int | None = None) -> None:
        # READ COMMITTED: each statement after the locks sees every commit made before they were granted (a
        # REPEATABLE READ snapshot would be taken by the lock's own statement, before the wait)
        if participant is None:
            con.execute("BEGIN ISOLATION LEVEL READ COMMITTED; SELECT pg_advisory_xact_lock(%d)" % WRITE_LOCK_KEY)
            return
        # the participant's lock first, then the database's shared (the order every transaction keeps); two
        # statements, so the second is asked only once the first is held; one round trip
        con.execute("BEGIN ISOLATION LEVEL READ COMMITTED; SELECT pg_advisory_xact_lock(%d, %d); "
                    "SELECT pg_advisory_xact_lock_shared(%d)" % (PARTICIPANT_LOCK_SPACE, int(participant),
                                                                 WRITE_LOCK_KEY))

    def hold(self, con: Connection, key: int, held: bool) -> None:
        # a session-level advisory lock in its own key space (two keys), apart from WRITE_LOCK_KEY's
        con.execute(f"SELECT {'pg_advisory_lock' if held else 'pg_advisory_unlock'}(%d, %d)"
                    % (PARTICIPANT_LOCK_SPACE, int(key)))

    def kind(self, exc: BaseException) -> str:
        import psycopg

        state = str(getattr(exc, "sqlstate", "") or "")
        if state == "53100" or state.startswith("53"):
            return "full"
        if state in ("42501", "25006", "28000", "28P01"):
            return "readonly"
        if state in ("55P03", "40001", "40P01", "57014"):
            return "busy"
        if state.startswith(("58", "XX")):
            return "damaged" if state in ("XX001", "XX002") else "io"
        if state.startswith(("08", "57P")) or (isinstance(exc, psycopg.OperationalError) and not state):
            return "unreachable"
        return "other"

    def problem(self, exc: BaseException, what: str) -> InputError:
        kind = self.kind(exc)
        text = " ".join(str(exc).split()) or type(exc).__name__
        if kind == "full":
            return InputError(self.target, None, f"the database server is out of disk space or memory ({text}): "
                              f"{what}. Free space on the server, then start again")
        if kind == "readonly":
            return InputError(self.target, None, f"the database user may not read or write the results tables "
                              f"({text}): {what}. Grant the user access to the database (or use its owner)")
        if kind == "busy":
            return InputError(self.target, None, f"the results database is locked by another program ({text}); "
                              f"{what}. Let it finish and start again")
        if kind == "unreachable":
            return InputError(self.target, None, f"cannot reach the PostgreSQL server ({text}): {what}. Check the "
                              "URL, that the server runs and that it accepts this user")
        if kind == "io":
            return InputError(self.target, None, f"the database server reported an error ({text}): {what}")
        return InputError(self.target, None, f"the results database is damaged or not a studyapp database "
                          f"({text}); keep a backup of it and use a new database")


class PgRow:
    """One result row, read like :class:`sqlite3.Row`: by index, by column name, ``dict(row)``, unpacking."""

    __slots__ = ("_names", "_values")

    def __init__(self, names: tuple[str, ...], values: tuple[Any, ...]) -> None:
        self._names = names
        self._values = values

    def keys(self) -> list[str]:
        return list(self._names)

    def __getitem__(self, key: int | str | slice) -> Any:
        if isinstance(key, str):
            return self._values[self._names.index(key)]
        return self._values[key]

    def __iter__(self) -> Iterator[Any]:
        return iter(self._values)

    def __len__(self) -> int:
        return len(self._values)

    def __repr__(self) -> str:
        return f"PgRow({dict(zip(self._names, self._values))!r})"


class PgCursor:
    """The rows of one statement as :class:`PgRow`; ``lastrowid`` is the inserted row's ``rowid``."""

    def __init__(self, cur: Any, drop_rowid: bool, lastrowid: int | None) -> None:
        self._cur = cur
        self.lastrowid = lastrowid
        desc = cur.description or []
        keep = [i for i, d in enumerate(desc) if not (drop_rowid and d.name == "rowid")]
        self._keep = keep if len(keep) != len(desc) else None
        self.description = [(desc[i].name, None, None, None, None, None, None) for i in (keep or range(len(desc)))] \
            if desc else None
        self._names = tuple(d[0] for d in self.description or ())
        self.rowcount = cur.rowcount

    def _row(self, values: tuple[Any, ...]) -> PgRow:
        if self._keep is not None:
            values = tuple(values[i] for i in self._keep)
        return PgRow(self._names, tuple(bytes(v) if isinstance(v, memoryview) else v for v in values))

    def fetchone(self) -> PgRow | None:
        if self._cur.description is None:
            return None
        row = self._cur.fetchone()
        return None if row is None else self._row(row)

    def fetchall(self) -> list[PgRow]:
        if self._cur.description is None:
            return []
        return [self._row(r) for r in self._cur.fetchall()]

    def __iter__(self) -> Iterator[PgRow]:
        return iter(self.fetchall())


# ---------------------------------------------------------------------------------------------- SQL rewriting
_SQLITE_MASTER = ("(SELECT table_name::text AS name, CASE table_type WHEN 'VIEW' THEN 'view' ELSE 'table' END AS type "
                  "FROM information_schema.tables WHERE table_schema = current_schema() "
                  f"AND table_name NOT LIKE '\\_studyapp\\_%') AS sqlite_master")
_PRAGMA_TABLE_INFO = re.compile(r"^\s*PRAGMA\s+table_info\(\s*\"?([^\")]+)\"?\s*\)\s*$", re.I)
_CAST_BLOB = re.compile(r"CAST\(([^()]+?) AS BLOB\)", re.I)
_INSERT_OR = re.compile(r"^\s*INSERT\s+OR\s+(IGNORE|REPLACE)\s+INTO\s+([\w.\"]+)\s*\(([^)]*)\)", re.I)
_INSERT_INTO = re.compile(r"^\s*INSERT\s+INTO\s+([\w.\"]+)", re.I)
_LEADING_COMMENTS = re.compile(r"^(?:\s*--[^\n]*(?:\n|$))+")
_CREATE_TABLE = re.compile(r"^\s*CREATE\s+TABLE\s+(?:IF\s+NOT\s+EXISTS\s+)?\"?(\w+)\"?", re.I)


@lru_cache(maxsize=512)
def _placeholders(sql: str) -> str:
    """``?`` -> ``%s`` outside quotes, every ``%`` doubled (psycopg reads ``%`` as a placeholder)."""
    out, quote = [], None
    for ch in sql:
        if quote:
            out.append("%%" if ch == "%" else ch)
            if ch == quote:
                quote = None
        elif ch in "'\"":
            quote = ch
            out.append(ch)
        elif ch == "?":
            out.append("%s")
        else:
            out.append("%%" if ch == "%" else ch)
    return "".join(out)


def create_table_ddl(sql: str) -> tuple[str, str, bool]:
    """SQLite's ``CREATE TABLE`` as PostgreSQL's, the table's name and whether it has a ``rowid`` (see the
    module docstring)."""
    name = _CREATE_TABLE.match(sql).group(1)  # type: ignore[union-attr]
    body = re.sub(r"--[^\n]*", "", sql).rstrip().rstrip(";").rstrip()
    without_rowid = re.search(r"\)\s*WITHOUT\s+ROWID$", body, re.I) is not None
    body = re.sub(r"\s*WITHOUT\s+ROWID$", "", body, flags=re.I)
    pk = re.search(r"(\w+)\s+INTEGER\s+PRIMARY\s+KEY", body, re.I)
    body = re.sub(r"INTEGER\s+PRIMARY\s+KEY\s+AUTOINCREMENT", "BIGINT GENERATED BY DEFAULT AS IDENTITY PRIMARY KEY",
                  body, flags=re.I)
    body = re.sub(r"\bINTEGER\b", "BIGINT", body, flags=re.I)
    body = re.sub(r"\bREAL\b", "DOUBLE PRECISION", body, flags=re.I)
    body = re.sub(r"\bBLOB\b", "BYTEA", body, flags=re.I)
    if not without_rowid:
        assert body.endswith(")"), body
        rowid = (f"rowid BIGINT GENERATED ALWAYS AS ({pk.group(1)}) STORED" if pk
                 else "rowid BIGINT GENERATED ALWAYS AS IDENTITY")
        body = f"{body[:-1].rstrip()},\n    {rowid}\n)"
    return body, name, not without_rowid


def _alter_ddl(sql: str) -> str:
    sql = re.sub(r"\bINTEGER\b", "BIGINT", sql, flags=re.I)
    sql = re.sub(r"\bREAL\b", "DOUBLE PRECISION", sql, flags=re.I)
    return re.sub(r"\bBLOB\b", "BYTEA", sql, flags=re.I)


@lru_cache(maxsize=512)
def translate(sql: str, pk: tuple[str, ...] = ()) -> str:
    """One statement of SQLite's SQL as PostgreSQL's (``pk``: the primary key, for ``INSERT OR REPLACE``)."""
    text = sql.strip().rstrip(";")
    if re.match(r"^\s*BEGIN\s*$", text, re.I):
        return "BEGIN ISOLATION LEVEL REPEATABLE READ"
    if re.match(r"^\s*ALTER\s+TABLE", text, re.I):
        return _alter_ddl(text)
    text = text.replace("sqlite_master", _SQLITE_MASTER)
    text = _CAST_BLOB.sub(lambda m: f"convert_to(({m.group(1)})::text, 'UTF8')", text)
    m = _INSERT_OR.match(text)
    if m:
        text = re.sub(r"^\s*INSERT\s+OR\s+(IGNORE|REPLACE)\s+INTO", "INSERT INTO", text, flags=re.I)
        if m.group(1).upper() == "IGNORE":
            text += " ON CONFLICT DO NOTHING"
        else:
            cols = [c.strip() for c in m.group(3).split(",")]
            sets = ", ".join(f"{c} = EXCLUDED.{c}" for c in cols if c not in pk)
            text += f" ON CONFLICT ({', '.join(pk)}) DO " + (f"UPDATE SET {sets}" if sets else "NOTHING")
    return text


def _plain_name(name: str) -> str:
    return name.strip('"').split(".")[-1]


class PgConnection:
    """A psycopg connection that runs storage's SQLite SQL (see :func:`translate`), read like sqlite3's.

    A connection the server dropped (a restart, a network cut, an idle timeout) is made again at the next
    statement that starts outside a transaction, so a long-running study server outlives its database
    server's restart; a transaction cut short is not repeated: its error reaches storage, which reports the
    change as not saved (nothing of it was committed).
    """

    def __init__(self, raw: Any, lock_timeout_s: float, reconnect: Any = None) -> None:
        self.raw = raw
        self.row_factory: Any = None  # rows are always PgRow (sqlite3.Row-like); kept for the same interface
        self._lock_timeout_s = lock_timeout_s
        self._reconnect = reconnect
        self._open_tx = False  # a transaction this connection began and has not ended
        self._settings()
        self._pk: dict[str, tuple[str, ...]] = {}
        self._has_rowid: dict[str, bool] = {}

    def _settings(self) -> None:
        self.raw.execute(f"SET synchronous_commit = on; SET lock_timeout = '{int(self._lock_timeout_s * 1000)}ms'")

    def _run(self, text: str, params: tuple | None) -> Any:
        import psycopg

        word = text.lstrip()[:8].upper()
        try:
            cur = self.raw.execute(text, params)
        except psycopg.OperationalError:
            ends = word.startswith(("COMMIT", "ROLLBACK"))
            if self._open_tx or self._reconnect is None or not (self.raw.closed or self.raw.broken):
                self._open_tx = self._open_tx and not ends
                raise  # a transaction cut short: storage reports its change as not saved
            # the server dropped the connection while no transaction was open: nothing was lost, connect again
            self.raw = self._reconnect()
            self._settings()
            cur = self.raw.execute(text, params)
        if word.startswith("BEGIN"):
            self._open_tx = True
        elif word.startswith(("COMMIT", "ROLLBACK")):
            self._open_tx = False
        return cur

    @property
    def in_transaction(self) -> bool:
        from psycopg import pq

        return self.raw.info.transaction_status != pq.TransactionStatus.IDLE

    def close(self) -> None:
        self.raw.close()

    # ------------------------------------------------------------------ catalog
    def _columns(self, table: str) -> list[tuple[str, str, bool, Any]]:
        # pg_catalog, not information_schema: read at every commit (the checksums), and many times faster
        return list(self.raw.execute(
            "SELECT a.attname::text, format_type(a.atttypid, a.atttypmod), a.attnotnull, "
            "pg_get_expr(d.adbin, d.adrelid) FROM pg_attribute a LEFT JOIN pg_attrdef d ON d.adrelid = a.attrelid "
            "AND d.adnum = a.attnum WHERE a.attrelid = to_regclass(%s) AND a.attnum > 0 AND NOT a.attisdropped "
            "ORDER BY a.attnum", (table,)))

    def primary_key(self, table: str) -> tuple[str, ...]:
        if table not in self._pk:
            rows = self.raw.execute(
                "SELECT a.attname::text FROM pg_index i JOIN pg_attribute a ON a.attrelid = i.indrelid "
                "AND a.attnum = ANY(i.indkey) WHERE i.indrelid = to_regclass(%s) AND i.indisprimary "
                "ORDER BY array_position(i.indkey::int2[], a.attnum)", (table,)).fetchall()
            self._pk[table] = tuple(r[0] for r in rows)
        return self._pk[table]

    def has_rowid(self, table: str) -> bool:
        if table not in self._has_rowid:
            self._has_rowid[table] = any(c[0] == "rowid" for c in self._columns(table))
        return self._has_rowid[table]

    def _table_info(self, table: str) -> list[tuple[Any, ...]]:
        pk = self.primary_key(table)
        return [(i, name, kind.upper(), int(notnull), default, (pk.index(name) + 1) if name in pk else 0)
                for i, (name, kind, notnull, default) in enumerate(c for c in self._columns(table) if c[0] != "rowid")]

    # ------------------------------------------------------------------ statements
    def _ensure_dirty_tracking(self) -> None:
        # the table and trigger function every studyapp table's trigger writes to (see row_checksums)
        self.raw.execute(f"CREATE TABLE IF NOT EXISTS {PG_DIRTY_TABLE} (xid BIGINT NOT NULL, tbl TEXT NOT NULL, "
                         "rid BIGINT NOT NULL)")
        if self.raw.execute("SELECT 1 FROM pg_proc WHERE proname = %s", (_PG_DIRTY_FUNC,)).fetchone() is None:
            self.raw.execute(
                f"CREATE FUNCTION {_PG_DIRTY_FUNC}() RETURNS trigger LANGUAGE plpgsql AS $$ BEGIN "
                f"IF TG_OP <> 'INSERT' THEN INSERT INTO {PG_DIRTY_TABLE} VALUES (txid_current(), TG_TABLE_NAME, "
                f"OLD.rowid); END IF; IF TG_OP <> 'DELETE' THEN INSERT INTO {PG_DIRTY_TABLE} VALUES "
                "(txid_current(), TG_TABLE_NAME, NEW.rowid); END IF; RETURN NULL; END $$")

    def _create_table(self, sql: str) -> Any:
        ddl, name, has_rowid = create_table_ddl(sql)
        self._ensure_dirty_tracking()
        cur = self.raw.execute(ddl)
        if has_rowid:
            self.raw.execute(f'CREATE TRIGGER _studyapp_dirty AFTER INSERT OR UPDATE OR DELETE ON "{name}" '
                             f"FOR EACH ROW EXECUTE FUNCTION {_PG_DIRTY_FUNC}()")
        self._pk.clear()
        self._has_rowid.clear()
        return cur

    def execute(self, sql: str, parameters: Sequence[Any] = ()) -> PgCursor:
        sql = _LEADING_COMMENTS.sub("", sql)
        m = _PRAGMA_TABLE_INFO.match(sql)
        if m:
            return _ListCursor(("cid", "name", "type", "notnull", "dflt_value", "pk"), self._table_info(m.group(1)))
        if _CREATE_TABLE.match(sql):
            return PgCursor(self._create_table(sql), False, None)
        if re.match(r"^\s*ALTER\s+TABLE", sql, re.I):
            self._has_rowid.clear()
        pk: tuple[str, ...] = ()
        ins = _INSERT_OR.match(sql)
        if ins and ins.group(1).upper() == "REPLACE":
            pk = self.primary_key(_plain_name(ins.group(2)))
        text = translate(sql, pk)
        returning = False
        ins_table = _INSERT_INTO.match(text)
        if ins_table and " RETURNING " not in text.upper() and self.has_rowid(_plain_name(ins_table.group(1))):
            text += " RETURNING rowid"
            returning = True
        params = tuple(parameters) if parameters else None
        cur = self._run(_placeholders(text) if params is not None else text, params)
        lastrowid = None
        if returning:
            row = cur.fetchone()
            lastrowid = None if row is None else int(row[0])
        drop = re.match(r"^\s*SELECT\s+\*", sql, re.I) is not None
        return PgCursor(cur, drop, lastrowid)

    def executemany(self, sql: str, seq_of_parameters: Any) -> PgCursor:
        pk: tuple[str, ...] = ()
        ins = _INSERT_OR.match(sql)
        if ins and ins.group(1).upper() == "REPLACE":
            pk = self.primary_key(_plain_name(ins.group(2)))
        cur = self.raw.cursor()
        cur.executemany(_placeholders(translate(sql, pk)), [tuple(p) for p in seq_of_parameters])
        return PgCursor(cur, False, None)


class _ListCursor(PgCursor):
    """Rows made here (the answer to ``PRAGMA table_info``), read like a statement's."""

    def __init__(self, names: tuple[str, ...], rows: list[tuple[Any, ...]]) -> None:  # noqa: D107
        self.lastrowid = None
        self.rowcount = len(rows)
        self.description = [(n, None, None, None, None, None, None) for n in names]
        self._names = names
        self._rows = [PgRow(names, tuple(r)) for r in rows]

    def fetchone(self) -> PgRow | None:
        return self._rows.pop(0) if self._rows else None

    def fetchall(self) -> list[PgRow]:
        out, self._rows = self._rows, []
        return out

    def __iter__(self) -> Iterator[PgRow]:
        return iter(self.fetchall())
