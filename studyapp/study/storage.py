"""Storage of study results: one database per study, every answer durable before the next clip.

The database is an SQLite file (the default) or a PostgreSQL database (a study server with several processes):
:func:`open_results` takes a path, ``sqlite:///path`` or ``postgresql://...``, and the same code writes the same
tables on both; what differs between the engines lives in :mod:`studyapp.study.sql_backend` (connecting, the
write lock, error messages, the SQL dialect). On PostgreSQL every commit waits for the server's WAL on disk
(``synchronous_commit = on``). Write transactions run one at a time on SQLite; on PostgreSQL those that write
only one participant's rows (an answer, a play, their session record: every method given the participant, see
:meth:`ResultsDB.transaction`) commit side by side with other participants', one at a time per participant,
while those that read or write across participants or the study's own rows (a new participant and their
Latin-square row, a participant removed or merged, the design's metadata, the schema) still run alone, as on
SQLite (:mod:`studyapp.study.sql_backend`, ``begin_write``). What follows describes the SQLite file; on
PostgreSQL the same checks run, except the file's own (header, ``PRAGMA integrity_check``).

Why these settings: ``journal_mode=WAL`` + ``synchronous=FULL`` make each committed transaction survive
a killed process or a power cut (the WAL is fsynced at commit), and a trial's ranks are written in one
transaction, so a crash leaves either the whole answer or none of it. Every result row carries the
design hash and the app version, so rows stay attributable after files are merged or moved.

The database checks itself when opened: not an SQLite file, a damaged file (``PRAGMA integrity_check``, a
superset of ``quick_check``, and every row against its checksum, see :mod:`studyapp.study.row_checksums`),
an unknown schema or a database made for another design each raise an :class:`InputError` that names the
file and says what to do. Every write transaction seals the checksums of the rows it wrote before it commits.
A full disk, a read-only file or folder and a lock held longer than :attr:`ResultsDB.LOCK_TIMEOUT_S` are each
their own one-line :class:`InputError` (:func:`sqlite_problem`), never "damaged": the change being written is
not stored and everything committed before it is kept. The tables are created in one write transaction that
first looks again for them, so two processes creating a new database at once both end up using it.

Example
-------
>>> import tempfile, pathlib
>>> db = ResultsDB(pathlib.Path(tempfile.mkdtemp()) / "s.sqlite", design_hash="ab12", title="Demo")
>>> db.add_participant("P01", n_rows=4).latin_row
0
>>> db.add_participant("P02", n_rows=4).latin_row
1
>>> db.close()
"""
from __future__ import annotations

import functools
import hashlib
import json
import logging
import platform
import random
import sqlite3
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Iterable, Iterator

from studyapp import __version__
from studyapp.errors import InputError, StudyappError
from studyapp.study import row_checksums, sql_backend
from studyapp.study.sql_backend import sqlite_problem  # noqa: F401  (its home was here; callers import it from here)

#: Bumped whenever the tables change; a database with another version is refused, never guessed at.
SCHEMA_VERSION = 7
#: Older schema versions this version upgrades in place when it opens them (see ``_MIGRATIONS``).
#: Version 2 added ``trials.trial_duration_s``; a version 1 trial keeps it NULL (not recorded).
#: Version 3 added ``trials.sample_left/middle/right`` (the sample each slot showed, see ``samples`` in
#: :class:`~studyapp.study.design.Condition`); an older trial keeps them NULL (not recorded).
#: Version 4 added ``conditions.label`` (the design's ``label``, NULL when the design gives none); an older
#: database keeps it NULL, and the analysis names such a condition by its id.
#: Version 5 added table ``row_checksums`` (see :mod:`studyapp.study.row_checksums`). A step needs no code
#: besides its SQL: once the table exists, :meth:`ResultsDB._migrate` verifies every row before each later
#: step and seals every row after it, so the upgrade that creates the table computes the checksums of the
#: rows already there (they are trusted as the file holds them then, after ``PRAGMA integrity_check``).
#: Version 6 added the response paradigms (see :class:`~studyapp.study.design.Block`): ``trials.block`` and
#: ``trials.paradigm`` (NULL in an upgraded database: block ``"main"``, paradigm ``"rank"``), table
#: ``trial_slots`` (every slot of every trial: condition, whose motion it played, sample) and table
#: ``judgements`` (pairwise/mismatch preferences and ratings, one row per slot). New parts use portable SQL
#: only (INTEGER/REAL/TEXT, no AUTOINCREMENT, no SQLite-only functions), so the same statements run on
#: PostgreSQL.
#: Version 7 added table ``criteria`` (each criterion's place in the design, its ``label`` and ``question`` in
#: the design's language), filled whenever the database is opened with its design; an upgraded database has
#: none until then, and the analysis names such a criterion by its id.
_MIGRATIONS = {1: ("ALTER TABLE trials ADD COLUMN trial_duration_s REAL",),
               2: ("ALTER TABLE trials ADD COLUMN sample_left INTEGER",
                   "ALTER TABLE trials ADD COLUMN sample_middle INTEGER",
                   "ALTER TABLE trials ADD COLUMN sample_right INTEGER"),
               3: ("ALTER TABLE conditions ADD COLUMN label TEXT",),
               4: (row_checksums.CREATE_TABLE,)}

PARTICIPANT_STATUSES = ("active", "done", "ended_early")
#: The key of a session's ``machine`` record that marks its participant abandoned: a browser participant who
#: left unfinished for longer than the design's ``[online] abandon_after_min`` (see :mod:`studyapp.web`). Such a
#: participant has status ``ended_early`` (the schema has no other status for it), keeps every answer given,
#: and no longer counts for the balance of Latin-square rows, so :meth:`ResultsDB.add_participant` gives the
#: row out again.
ABANDONED = "abandoned_at"

_SCHEMA = """
CREATE TABLE schema_version (version INTEGER NOT NULL);
CREATE TABLE study (
    id INTEGER PRIMARY KEY CHECK (id = 1),
    design_hash TEXT NOT NULL,
    title TEXT NOT NULL,
    created TEXT NOT NULL,
    app_version TEXT NOT NULL
);
-- Study metadata copied from the design, so an export needs only the database.
CREATE TABLE stimuli (
    id TEXT PRIMARY KEY,
    tags TEXT NOT NULL DEFAULT '{}'
);
-- position: the condition's place in the design (the analysis's order), label: the design's label (NULL:
-- none given, the analysis shows the id), last so an upgraded version 3 database has the same column order
CREATE TABLE conditions (
    id TEXT PRIMARY KEY,
    position INTEGER NOT NULL,
    label TEXT
);
CREATE TABLE participants (
    id TEXT PRIMARY KEY,
    latin_row INTEGER NOT NULL,
    groups TEXT NOT NULL DEFAULT '{}',
    status TEXT NOT NULL DEFAULT 'active' CHECK (status IN ('active', 'done', 'ended_early')),
    created TEXT NOT NULL,
    completed TEXT,
    design_hash TEXT NOT NULL,
    app_version TEXT NOT NULL
);
CREATE TABLE sessions (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    participant TEXT NOT NULL REFERENCES participants(id),
    started TEXT NOT NULL,
    ended TEXT,
    app_version TEXT NOT NULL,
    design_hash TEXT NOT NULL,
    machine TEXT NOT NULL DEFAULT '{}'
);
CREATE TABLE trials (
    participant TEXT NOT NULL REFERENCES participants(id),
    trial_index INTEGER NOT NULL,
    session INTEGER REFERENCES sessions(id),
    stimulus TEXT NOT NULL,
    is_practice INTEGER NOT NULL,
    is_attention_check INTEGER NOT NULL,
    slot_left TEXT NOT NULL,
    slot_middle TEXT NOT NULL,
    slot_right TEXT NOT NULL,
    shown_at TEXT,
    answered_at TEXT NOT NULL,
    response_time_s REAL,
    plays INTEGER NOT NULL DEFAULT 0,
    frames_shown INTEGER,
    dropped_frames INTEGER,
    refresh_hz REAL,
    worst_av_offset_ms REAL,
    attention_passed INTEGER,
    design_hash TEXT NOT NULL,
    app_version TEXT NOT NULL,
    -- seconds the trial played (its timeline: the stimulus's duration_s, else the audio's length), last
    -- so a database upgraded from version 1 (ALTER TABLE ADD COLUMN) has the same column order
    trial_duration_s REAL,
    -- the 1-based sample of its condition each slot showed (1 for a condition with one motion per stimulus),
    -- after trial_duration_s for the same reason
    sample_left INTEGER,
    sample_middle INTEGER,
    sample_right INTEGER,
    -- the trial's block and paradigm (schema 6, NULL in an upgraded database: "main", "rank"). Slots of a
    -- two-slot trial are (left, '', right), of a four-slot one the first three: trial_slots has them all
    block TEXT,
    paradigm TEXT,
    PRIMARY KEY (participant, trial_index)
);
CREATE TABLE responses (
    participant TEXT NOT NULL,
    trial_index INTEGER NOT NULL,
    criterion TEXT NOT NULL,
    condition TEXT NOT NULL,
    slot INTEGER NOT NULL CHECK (slot BETWEEN 0 AND 2),
    rank REAL NOT NULL,
    design_hash TEXT NOT NULL,
    app_version TEXT NOT NULL,
    PRIMARY KEY (participant, trial_index, criterion, slot),
    FOREIGN KEY (participant, trial_index) REFERENCES trials(participant, trial_index)
);
CREATE TABLE plays (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    participant TEXT NOT NULL REFERENCES participants(id),
    trial_index INTEGER NOT NULL,
    session INTEGER REFERENCES sessions(id),
    started TEXT NOT NULL,
    ended TEXT,
    completed INTEGER NOT NULL DEFAULT 0,
    design_hash TEXT NOT NULL,
    app_version TEXT NOT NULL
);
CREATE TABLE questionnaire (
    participant TEXT NOT NULL REFERENCES participants(id),
    item TEXT NOT NULL,
    kind TEXT NOT NULL DEFAULT 'likert',
    scale TEXT,
    value TEXT,
    design_hash TEXT NOT NULL,
    app_version TEXT NOT NULL,
    PRIMARY KEY (participant, item)
);
-- Every slot of every trial (schema 6): its condition, the stimulus whose motion it played (a mismatch
-- trial's other clip) and the sample shown: the full truth for trials of 2 or 4 slots.
CREATE TABLE trial_slots (
    participant TEXT NOT NULL,
    trial_index INTEGER NOT NULL,
    slot INTEGER NOT NULL,
    condition TEXT NOT NULL,
    motion_stimulus TEXT NOT NULL,
    sample INTEGER,
    design_hash TEXT NOT NULL,
    app_version TEXT NOT NULL,
    PRIMARY KEY (participant, trial_index, slot),
    FOREIGN KEY (participant, trial_index) REFERENCES trials(participant, trial_index)
);
-- Answers of pairwise, mismatch and rating trials, one row per criterion x slot (schema 6): the preference
-- FOR that slot (+2 clearly this one .. -2 clearly the other, a trial's two rows are p and -p) or its rating
-- 0..100. reasons: a JSON list of the reasons chosen (pairwise), on both rows of a trial.
CREATE TABLE judgements (
    participant TEXT NOT NULL,
    trial_index INTEGER NOT NULL,
    criterion TEXT NOT NULL,
    slot INTEGER NOT NULL,
    condition TEXT NOT NULL,
    value REAL NOT NULL,
    reasons TEXT,
    design_hash TEXT NOT NULL,
    app_version TEXT NOT NULL,
    PRIMARY KEY (participant, trial_index, criterion, slot),
    FOREIGN KEY (participant, trial_index) REFERENCES trials(participant, trial_index)
);
-- The design's criteria (schema 7): position is its place in the design, label and question the text the
-- participants read (in the design's language): the analysis shows the label (the id when none is stored)
CREATE TABLE criteria (
    id TEXT PRIMARY KEY,
    position INTEGER NOT NULL,
    label TEXT NOT NULL,
    question TEXT NOT NULL
);
-- Keys of remote bundles made from this study: opaque condition ids -> real ids (see bundle.py).
CREATE TABLE bundles (
    design_hash TEXT PRIMARY KEY,
    created TEXT NOT NULL,
    key TEXT NOT NULL
);
-- The checksum of every row of every other table (see row_checksums.py).
""" + row_checksums.CREATE_TABLE + ";\n"


def _create_statement(table: str) -> str:
    """The ``CREATE TABLE`` statement of ``table`` in :data:`_SCHEMA` (so a migration creates it identically)."""
    start = _SCHEMA.index(f"CREATE TABLE {table} (")
    return _SCHEMA[start:_SCHEMA.index(";", start)]


_MIGRATIONS[5] = ("ALTER TABLE trials ADD COLUMN block TEXT", "ALTER TABLE trials ADD COLUMN paradigm TEXT",
                  _create_statement("trial_slots"), _create_statement("judgements"))
_MIGRATIONS[6] = (_create_statement("criteria"),)

assert not any(";" in ln for ln in _SCHEMA.splitlines() if ln.strip().startswith("--")), \
    "a ';' in a comment of _SCHEMA would split its statement"

#: Tables (and their columns) a valid database must have; used to recognise a foreign schema.
_EXPECTED_TABLES = {
    "schema_version", "study", "stimuli", "conditions", "participants", "sessions", "trials",
    "responses", "plays", "questionnaire", "bundles",
}
#: Tables a database of the current version has besides those (an older one gains them when upgraded).
_NEW_TABLES = ("trial_slots", "judgements", "criteria")




@functools.lru_cache(maxsize=1)
def _expected_columns() -> dict[str, tuple[str, ...]]:
    """Each table of the current schema and its columns, read from :data:`_SCHEMA` made in memory."""
    con = sqlite3.connect(":memory:")
    try:
        con.executescript(_SCHEMA)
        names = [r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type = 'table'")
                 if not r[0].startswith("sqlite_")]
        return {t: tuple(r[1] for r in con.execute(f"PRAGMA table_info({t})")) for t in names}
    finally:
        con.close()


_log = logging.getLogger(__name__)

_NOT_SAVED = "the last change (e.g. the answer just given) was not saved; everything saved before it is kept"


def now_iso() -> str:
    """Current UTC time as ISO 8601 with milliseconds (sortable text, unambiguous across machines)."""
    return datetime.now(timezone.utc).isoformat(timespec="milliseconds")


class DuplicateAnswerError(StudyappError):
    """A trial that already has an answer was submitted again (answers are never overwritten)."""


@dataclass
class ParticipantRecord:
    """One participant as stored: the Latin-square row they follow and their groups."""

    id: str
    latin_row: int
    groups: dict[str, str] = field(default_factory=dict)
    status: str = "active"
    created: str = ""
    completed: str | None = None


@dataclass
class TrialRecord:
    """Everything stored about one answered trial besides the ranks themselves.

    ``slots`` are condition ids left to right (3 for rank, 2 pairwise/mismatch, k rating), ``samples`` the
    1-based sample each slot showed; ``attention_passed`` is ``None`` for a trial that is not an attention check.
    """

    participant: str
    trial_index: int
    stimulus: str
    is_practice: bool
    is_attention_check: bool
    slots: tuple[str, ...]
    answered_at: str
    shown_at: str | None = None
    response_time_s: float | None = None
    plays: int = 0
    frames_shown: int | None = None
    dropped_frames: int | None = None
    refresh_hz: float | None = None
    worst_av_offset_ms: float | None = None
    attention_passed: bool | None = None
    session: int | None = None
    trial_duration_s: float | None = None
    samples: tuple[int | None, ...] = (1, 1, 1)
    block: str = "main"
    paradigm: str = "rank"
    #: per slot, the stimulus whose motion it played; () = ``stimulus`` for every slot
    motion_stimuli: tuple[str, ...] = ()


@dataclass(frozen=True)
class Judgement:
    """One slot's answer on one criterion of a pairwise, mismatch or rating trial (table ``judgements``):
    ``value`` is the preference for this slot (-2..2) or its rating (0..100); ``reasons`` the chosen reasons."""

    criterion: str
    condition: str
    slot: int
    value: float
    reasons: tuple[str, ...] = ()


@dataclass(frozen=True)
class Response:
    """One rank: ``condition`` shown in ``slot`` (0 left, 1 middle, 2 right) got ``rank`` on ``criterion``."""

    criterion: str
    condition: str
    slot: int
    rank: float


def machine_basics() -> dict[str, str]:
    """Operating system facts recorded with every session (the UI adds GL, display and audio facts)."""
    return {
        "os": platform.platform(),
        "python": platform.python_version(),
        "machine": platform.machine(),
    }  # no host name: on a participant's own PC it can identify them


#: The columns each writer fills, per table (design_hash is added to every row): the one list of what a
#: results row holds, shared by the participant's session (``save_trial``) and merging (``import_participant``).
_WRITTEN: dict[str, tuple[str, ...]] = {
    "participants": ("id", "latin_row", "groups", "status", "created", "completed", "app_version"),
    "sessions": ("participant", "started", "ended", "app_version", "machine"),
    "trials": ("participant", "trial_index", "session", "stimulus", "is_practice", "is_attention_check", "slot_left",
               "slot_middle", "slot_right", "shown_at", "answered_at", "response_time_s", "plays", "frames_shown",
               "dropped_frames", "refresh_hz", "worst_av_offset_ms", "attention_passed", "app_version",
               "trial_duration_s", "sample_left", "sample_middle", "sample_right", "block", "paradigm"),
    "trial_slots": ("participant", "trial_index", "slot", "condition", "motion_stimulus", "sample", "app_version"),
    "responses": ("participant", "trial_index", "criterion", "condition", "slot", "rank", "app_version"),
    "judgements": ("participant", "trial_index", "criterion", "slot", "condition", "value", "reasons",
                   "app_version"),
    "plays": ("participant", "trial_index", "session", "started", "ended", "completed", "app_version"),
    "questionnaire": ("participant", "item", "kind", "scale", "value", "app_version"),
}
#: The tables whose rows are keyed by an id the database gives (a caller may need the new ones).
_ROW_IDS = ("sessions", "plays")


def lock_key(name: str) -> int:
    """The key (a signed 32-bit number) of the lock of ``name`` (a participant's id): the same in every process,
    for :meth:`ResultsDB.exclusive` and for a transaction of that participant's rows (:meth:`ResultsDB.transaction`),
    so a request that holds it writes without waiting for itself."""
    return int.from_bytes(hashlib.sha256(name.encode("utf-8")).digest()[:4], "big", signed=True)


def open_results(target: str | Path, design: Any = None, **options: Any) -> "ResultsDB":
    """The results database ``target`` names: a path or ``sqlite:///path`` (an SQLite file) or
    ``postgresql://USER@HOST:PORT/DATABASE`` (an existing PostgreSQL database; its tables are created on first
    use). ``design`` and ``options`` are :class:`ResultsDB`'s."""
    return ResultsDB(sql_backend.results_target(target) if isinstance(target, str) else target, design, **options)


class ResultsDB:
    """The results database of one study.

    Parameters
    ----------
    path:
        The SQLite file; created (with its folder) when missing and ``create`` is true. A ``postgresql://``
        URL opens a PostgreSQL database instead (see :func:`open_results`).
    design:
        The loaded design (anything with ``design_hash``, ``title`` and, optionally, ``stimuli`` /
        ``conditions``). A new database is stamped with its hash; an existing one must carry the same hash.
    design_hash, title:
        Alternatives to ``design`` for callers that have no design object (tests, merge tools).
        With neither, an existing database is opened as it is (export, merge).
    create:
        With ``False`` a missing file is an error instead of a new database.
    """

    #: How long to wait for another connection's lock (a second lab station committing) before giving up.
    LOCK_TIMEOUT_S = 30.0

    def __init__(
        self,
        path: str | Path,
        design: Any = None,
        *,
        design_hash: str | None = None,
        title: str | None = None,
        create: bool = True,
    ) -> None:
        self._backend = sql_backend.backend_for(path)
        #: Inside :meth:`batch`: how many savepoints it has made; None outside one.
        self._batch: int | None = None
        #: The file, or (PostgreSQL) the URL without its password: what messages name.
        self.path: Path | str = self._backend.target
        if design is not None:
            design_hash = design.design_hash
            title = design.title
        exists = self._backend.exists()
        if not exists and not create:
            raise InputError(self.path, None, "results database not found; check the path")
        if not exists and design_hash is None:
            raise InputError(self.path, None, "results database not found, and no design was given to create one")
        self._backend.check_before_open(exists, writing=design_hash is not None)
        self._con: Any = self._backend.connect(self.LOCK_TIMEOUT_S)
        # Some lock conflicts of a brand-new file (switching it to WAL while another process creates it) are
        # reported at once, without SQLite's busy wait: every step below is safe to repeat, so wait and retry
        # for as long as a held lock may take, then say it is locked.
        give_up = time.monotonic() + self.LOCK_TIMEOUT_S
        while True:
            try:
                row = self._open_steps(exists, design_hash, title)
                break
            except (*self._backend.errors, UnicodeDecodeError) as exc:  # damaged text in SQLite's tables cannot decode
                if isinstance(exc, self._backend.errors) and self._backend.kind(exc) == "busy" \
                        and time.monotonic() < give_up:
                    time.sleep(0.05 + 0.05 * random.random())
                    continue
                self._con.close()
                raise self._backend.problem(exc, "the results database could not be created or opened") from None
            except BaseException:
                self._con.close()
                raise
        if row is None:
            self._con.close()
            raise InputError(self.path, "table study", "the study record is missing; the file is not a complete "
                             "studyapp results database")
        self.design_hash: str = row["design_hash"]
        self.title: str = row["title"]
        if design_hash is not None and design_hash != self.design_hash:
            self._con.close()
            raise InputError(
                self.path, "study.design_hash",
                f"this results database belongs to another design (hash {self.design_hash[:12]}…, this design is "
                f"{design_hash[:12]}…): the design or one of its stimuli changed since the first participant. "
                "Use a new results file (--results) or restore the original design",
            )
        if design is not None:
            try:
                self.store_design_metadata(design)
            except BaseException:
                self._con.close()
                raise
        #: Optional ``f(participant_id) -> Path`` called when a participant finishes (set by bundle runs).
        self.on_participant_finished: Any = None

    # ------------------------------------------------------------------ opening and checking
    def _open_steps(self, exists: bool, design_hash: str | None, title: str | None) -> Any:
        """Configure, check (or create) the database and return its study row; each step may be repeated."""
        self._configure()
        if exists:
            self._check_integrity()
        # A process killed while creating the database can leave a valid SQLite file with no tables
        # (the schema is one transaction): that is still a new database, not a foreign one.
        if not (design_hash is not None and self._create_if_empty(design_hash, title or "")):
            if not self._con.execute("SELECT 1 FROM sqlite_master LIMIT 1").fetchone():
                raise InputError(self.path, None, "the results database is empty, and no design was given to "
                                 "create it")
            self._check_schema()
            self._check_rows()
        row_checksums.install_triggers(self._con)
        return self._con.execute("SELECT design_hash, title FROM study WHERE id = 1").fetchone()

    def _configure(self) -> None:
        self._backend.configure(self._con)

    def _check_integrity(self) -> None:
        rows = self._backend.integrity_check(self._con)
        if rows != ["ok"]:
            # One result row may hold dozens of lines (one per damaged cell): count lines, show only a few,
            # so the message stays readable while still saying how much is wrong.
            problems = [ln.strip() for r in rows for ln in r.splitlines()
                        if ln.strip() and not ln.startswith("*** in database")]
            shown = "; ".join(problems[:3]) + (f" (+{len(problems) - 3} more)" if len(problems) > 3 else "")
            raise InputError(self.path, "integrity check", f"the results database is damaged: {shown}. Keep a "
                             "copy of the file for recovery and start a new one with --results")

    def _check_schema(self) -> None:
        tables = {r[0] for r in self._con.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
        missing = sorted(_EXPECTED_TABLES - tables)
        if missing:
            raise InputError(self.path, "schema", f"not a studyapp results database (missing tables: "
                             f"{', '.join(missing)})")
        row = self._con.execute("SELECT version FROM schema_version").fetchone()
        if row is not None and row[0] in _MIGRATIONS:
            self._migrate(int(row[0]))
            row = self._con.execute("SELECT version FROM schema_version").fetchone()
        if row is None or row[0] != SCHEMA_VERSION:
            found = None if row is None else row[0]
            raise InputError(self.path, "schema_version", f"schema version {found} is not the version this "
                             f"studyapp {__version__} writes ({SCHEMA_VERSION}); use the studyapp version "
                             "that created the file")
        for table in (row_checksums.TABLE, *_NEW_TABLES):
            if not self._has_table(table):
                raise InputError(self.path, "schema", f"table {table} is missing: the file is damaged or not a "
                                 "complete studyapp results database. Keep a copy of it for recovery")
        # A damaged table definition (a flipped bit in a column's name) passes the integrity check and would
        # surface later as an SQL error in a query: every column the tables must have is looked for now.
        for table, columns in _expected_columns().items():
            have = {r[1] for r in self._con.execute(f"PRAGMA table_info({table})")}
            lost = [c for c in columns if c not in have]
            if lost:
                raise InputError(self.path, "schema", f"table {table} has no column {', '.join(lost)}: the file is "
                                 "damaged or not a complete studyapp results database. Keep a copy of it for "
                                 "recovery")

    def _has_table(self, name: str) -> bool:
        return self._con.execute("SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = ?",
                                 (name,)).fetchone() is not None

    def _check_rows(self) -> None:
        """Every row against its checksum: a damaged value is reported, never read as data."""
        # one read transaction: another station committing meanwhile must not look like a row without checksum
        self._con.execute("BEGIN")
        try:
            problems = row_checksums.verify(self._con)
        finally:
            self._con.execute("COMMIT")
        if problems:
            shown = "; ".join(problems[:3]) + (f" (+{len(problems) - 3} more)" if len(problems) > 3 else "")
            raise InputError(self.path, "row checksums", f"the results database is damaged: {shown}. Nothing was "
                             "read from it; keep a copy of the file for recovery, and restore a backup or start a "
                             "new one with --results")

    def _migrate(self, version: int) -> None:
        """Upgrade an older database in place, one version at a time, each step in one transaction (all of a
        step or none of it), so old results stay readable and new answers can join them.

        Once the database has row checksums, every row is verified before a step and sealed after it (a new
        column changes every row's checksum); the step that creates the checksum table seals the rows there.
        """
        start = version
        while version in _MIGRATIONS:
            if self._has_table(row_checksums.TABLE):
                self._check_rows()
            with self.transaction(f"upgrading the results database from schema version {version} was undone; "
                                  "every result in it is kept") as con:
                now = con.execute("SELECT version FROM schema_version").fetchone()
                if now is None or now[0] != version:  # another process upgraded it while this one waited
                    version = SCHEMA_VERSION if now is None else int(now[0])
                    continue
                for stmt in _MIGRATIONS[version]:
                    con.execute(stmt)
                version += 1
                con.execute("UPDATE schema_version SET version = ?", (version,))
                if self._has_table(row_checksums.TABLE):
                    row_checksums.seal_all(con)
        _log.info("%s: upgraded the results database from schema version %d to %d in place; every row now "
                  "carries a checksum (rows stored before are taken as the file held them)", self.path, start, version)

    def _create_if_empty(self, design_hash: str, title: str) -> bool:
        """Create the tables when the database has none; False (nothing done) when it has them.

        The check and the creation are one write transaction: two participants starting at once on a new
        database serialise on its lock, and the second finds the tables the first created.
        """
        if self._con.execute("SELECT 1 FROM sqlite_master LIMIT 1").fetchone():
            return False
        with self.transaction("the new results database could not be created (nothing was recorded yet)") as con:
            if con.execute("SELECT 1 FROM sqlite_master LIMIT 1").fetchone():
                return False
            for stmt in _SCHEMA.split(";"):
                if stmt.strip():
                    con.execute(stmt)
            con.execute("INSERT INTO schema_version (version) VALUES (?)", (SCHEMA_VERSION,))
            con.execute("INSERT INTO study (id, design_hash, title, created, app_version) VALUES (1, ?, ?, ?, ?)",
                        (design_hash, title, now_iso(), __version__))
            row_checksums.seal_all(con)
        return True

    def store_design_metadata(self, design: Any) -> None:
        """Record what an export needs of ``design`` (its stimuli's tags, its conditions' and criteria's places
        and labels), keeping what is stored already: called when the database is opened with its design, and
        by merge, which opens it without and then loads the design (an upgraded database gains its labels)."""
        stimuli = getattr(design, "stimuli", None) or []
        conditions = getattr(design, "conditions", None) or []
        criteria = getattr(design, "criteria", None) or []
        with self.transaction() as con:
            for s in stimuli:
                con.execute("INSERT OR IGNORE INTO stimuli (id, tags) VALUES (?, ?)",
                            (s.id, json.dumps(dict(getattr(s, "tags", {}) or {}), sort_keys=True)))
            for i, c in enumerate(conditions):
                con.execute("INSERT OR IGNORE INTO conditions (id, position, label) VALUES (?, ?, ?)",
                            (c.id, i, getattr(c, "label", None)))
            for i, c in enumerate(criteria):
                con.execute("INSERT OR IGNORE INTO criteria (id, position, label, question) VALUES (?, ?, ?, ?)",
                            (c.id, i, getattr(c, "label", None) or c.id, getattr(c, "question", None) or ""))

    # ------------------------------------------------------------------ plumbing
    @property
    def connection(self) -> sqlite3.Connection:
        """The raw connection, for read-only queries (export); write through the methods. On PostgreSQL a
        :class:`~studyapp.study.sql_backend.PgConnection`, which reads the same SQL."""
        return self._con

    @property
    def backend(self) -> str:
        """Where the database lives: ``"sqlite"`` or ``"postgresql"``."""
        return self._backend.name

    class _Tx:
        def __init__(self, con: sqlite3.Connection, backend: sql_backend.Backend, what: str,
                     nested: int | None = None, participant: int | None = None) -> None:
            self.con = con
            self.backend = backend
            self.what = what
            #: the key of the participant whose rows alone this transaction writes (None: any rows)
            self.participant = participant
            #: inside :meth:`ResultsDB.batch`: this transaction's savepoint number (its COMMIT is the batch's)
            self.nested = nested

        def __enter__(self) -> sqlite3.Connection:
            if self.nested is not None:
                # the batch's transaction must still be open: an engine error may have rolled it back, and a
                # savepoint outside a transaction would commit on its own, ahead of the batch's one answer
                if not self.con.in_transaction:
                    raise InputError(self.backend.target, None, f"{self.what} (an earlier error ended the "
                                     "transaction of this group of requests)")
                self.con.execute(f"SAVEPOINT tx{self.nested}")
                return self.con
            # the write lock up front (SQLite: BEGIN IMMEDIATE), so two processes on one database serialise
            # (e.g. two lab PCs assigning Latin rows) instead of failing half-way.
            try:
                self.backend.begin_write(self.con, self.participant)
            except self.backend.errors as exc:
                self._rollback()
                raise self.backend.problem(exc, self.what) from None
            return self.con

        def __exit__(self, exc_type, exc, tb) -> None:
            if self.nested is not None:
                self._leave_savepoint(exc_type is None)
                if isinstance(exc, self.backend.errors) and self.backend.kind(exc) != "other":
                    raise self.backend.problem(exc, self.what) from None
                return
            if exc_type is None:
                try:
                    # the checksums of the rows this transaction wrote, in the same transaction
                    row_checksums.seal_dirty(self.con)
                    self.con.execute("COMMIT")
                    return
                except self.backend.errors as failed:
                    exc = failed
            self._rollback()
            if isinstance(exc, self.backend.errors) and self.backend.kind(exc) != "other":
                # a full disk, a read-only folder, a lock held too long: one line that says what to do
                raise self.backend.problem(exc, self.what) from None
            if exc_type is None:
                raise exc

        def _leave_savepoint(self, keep: bool) -> None:
            # kept: its rows are sealed with the batch's commit; undone: as if it never ran
            name = f"tx{self.nested}"
            try:
                if not keep:
                    self.con.execute(f"ROLLBACK TO {name}")
                self.con.execute(f"RELEASE {name}")
            except self.backend.errors as exc:
                if keep:
                    raise self.backend.problem(exc, self.what) from None

        def _rollback(self) -> None:
            # leave no half-open transaction behind; a failing ROLLBACK (the disk gone) changes nothing on disk
            try:
                if self.con.in_transaction:
                    self.con.execute("ROLLBACK")
            except self.backend.errors:
                pass

    @contextmanager
    def exclusive(self, name: str) -> Iterator[None]:
        """``with db.exclusive(participant_id):`` — run this block alone among every connection to the database
        that asks for the same name (PostgreSQL: an advisory lock, so several server processes never interleave
        two requests of one participant; SQLite: nothing, one server process already does)."""
        key = lock_key(name)
        try:
            self._backend.hold(self._con, key, True)
        except self._backend.errors as exc:
            raise self._backend.problem(exc, "the request waited too long for the participant's previous one") from None
        try:
            yield
        finally:
            try:
                self._backend.hold(self._con, key, False)
            except self._backend.errors:
                pass   # the connection is gone, and its session-level lock with it

    def transaction(self, what: str = _NOT_SAVED, participant: str | None = None) -> "ResultsDB._Tx":
        """``with db.transaction() as con:`` — all statements inside commit together or not at all, with the
        checksums of every row they wrote; a full disk, a read-only file or a lock held too long raise
        :class:`InputError` (nothing of the transaction is stored; ``what`` says so in the message).

        ``participant``: the transaction reads and writes only that participant's rows (none of another
        participant's, none of the study's), and its result depends on no other participant's: on PostgreSQL
        it then commits beside other participants' transactions (one at a time per participant); without it,
        it runs alone (see :mod:`studyapp.study.sql_backend`). SQLite runs every write alone either way."""
        if self._batch is not None:
            self._batch += 1
            return ResultsDB._Tx(self._con, self._backend, what, nested=self._batch)
        return ResultsDB._Tx(self._con, self._backend, what,
                             participant=None if participant is None else lock_key(participant))

    def _owner(self, table: str, row_id: int) -> str | None:
        """The participant a row of ``sessions`` or ``plays`` belongs to (it never changes), for
        :meth:`transaction`: None (a transaction that runs alone) where every write runs alone anyway (SQLite:
        no read for nothing), or when there is no such row (the write then changes nothing)."""
        if self._backend.name == "sqlite":
            return None
        row = self._con.execute(f"SELECT participant FROM {table} WHERE id = ?", (row_id,)).fetchone()
        return None if row is None else str(row[0])

    @contextmanager
    def batch(self, what: str = _NOT_SAVED) -> Iterator[None]:
        """``with db.batch():`` — group commit: every :meth:`transaction` inside is a savepoint of one write
        transaction, committed (with every checksum) when the block ends, so many small changes cost one fsync.
        A transaction that fails is undone alone, as it would be on its own; when the commit fails nothing of the
        block is stored and the error is raised (an :class:`InputError`, as :meth:`transaction`'s). Nothing done
        inside is durable before the block ends: a caller answers only then (the study server's database thread,
        :mod:`studyapp.web.dbthread`)."""
        if self._batch is not None:
            raise RuntimeError("batches do not nest")
        with self.transaction(what):
            self._batch = 0
            try:
                yield
            finally:
                self._batch = None

    def twin(self) -> "ResultsDB":
        """Another connection to this database, for another thread: a long read that must not hold up this
        connection (the study server's export), or one more of a server's database threads on PostgreSQL.
        Opened without checking the database again (this one did); close it when done."""
        twin = object.__new__(ResultsDB)
        twin.__dict__.update(self.__dict__)
        twin._batch = None
        twin.on_participant_finished = None
        twin._con = self._backend.connect(self.LOCK_TIMEOUT_S)
        try:
            self._backend.configure(twin._con)
        except self._backend.errors as exc:
            twin.close()
            raise self._backend.problem(exc, "the results database could not be opened for reading") from None
        return twin

    def close(self) -> None:
        try:
            self._con.close()
        except self._backend.errors:
            pass

    def __enter__(self) -> "ResultsDB":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ study metadata
    def stimulus_tags(self) -> dict[str, dict[str, str]]:
        return {r["id"]: json.loads(r["tags"]) for r in self._con.execute("SELECT id, tags FROM stimuli")}

    def condition_ids(self) -> list[str]:
        return [r[0] for r in self._con.execute("SELECT id FROM conditions ORDER BY position")]

    def criteria(self) -> list[dict[str, Any]]:
        """The stored criteria (id, position, label, question) in the design's order."""
        return [dict(r) for r in self._con.execute("SELECT * FROM criteria ORDER BY position")]

    # ------------------------------------------------------------------ participants
    @staticmethod
    def _participant(row: sqlite3.Row) -> ParticipantRecord:
        return ParticipantRecord(id=row["id"], latin_row=row["latin_row"], groups=json.loads(row["groups"]),
                                 status=row["status"], created=row["created"], completed=row["completed"])

    def participant(self, participant_id: str) -> ParticipantRecord | None:
        row = self._con.execute("SELECT * FROM participants WHERE id = ?", (participant_id,)).fetchone()
        return None if row is None else self._participant(row)

    def participants(self) -> list[ParticipantRecord]:
        return [self._participant(r) for r in self._con.execute("SELECT * FROM participants ORDER BY created, id")]

    def participant_ids(self) -> list[str]:
        """Every participant's id (what :meth:`participants` reads, without decoding each record)."""
        return [r[0] for r in self._con.execute("SELECT id FROM participants ORDER BY created, id")]

    def row_counts(self, n_rows: int) -> list[int]:
        """How many participants follow each Latin-square row ``0 .. n_rows-1``. A participant who declined
        consent or was abandoned (status ``ended_early`` with ``"consent": "declined"`` or :data:`ABANDONED` in a
        session's machine record) saw no trial, or no longer will, and holds no row."""
        counts = [0] * n_rows
        for r in self._con.execute(
                "SELECT latin_row, COUNT(*) FROM participants p WHERE NOT (p.status = 'ended_early' AND EXISTS "
                "(SELECT 1 FROM sessions s WHERE s.participant = p.id AND (s.machine LIKE ? OR s.machine LIKE ?))) "
                "GROUP BY latin_row", (f'%"{ABANDONED}"%', '%"consent": "declined"%')):
            if 0 <= r[0] < n_rows:
                counts[r[0]] = r[1]
        return counts

    def add_participant(self, participant_id: str, n_rows: int, row: int | None = None,
                        groups: dict[str, str] | None = None) -> ParticipantRecord:
        """Register a new participant on ``row`` or, when ``None``, on the least used row (lowest index on ties).

        The choice and the insert happen in one write transaction, so concurrent sessions never pick the
        same "free" row from a stale count.
        """
        if not participant_id or not participant_id.strip():
            raise InputError(None, "participant id", "the participant id is empty")
        if row is not None and not (0 <= row < n_rows):
            raise InputError(self.path, "--row", f"row {row} is outside the design's Latin square rows 0..{n_rows - 1}")
        with self.transaction() as con:
            if con.execute("SELECT 1 FROM participants WHERE id = ?", (participant_id,)).fetchone():
                raise StudyappError(f"participant {participant_id!r} is already in {self.path}")
            if row is None:
                counts = self.row_counts(n_rows)
                row = counts.index(min(counts))
            con.execute(
                "INSERT INTO participants (id, latin_row, groups, status, created, design_hash, app_version) "
                "VALUES (?, ?, ?, 'active', ?, ?, ?)",
                (participant_id, row, json.dumps(groups or {}, sort_keys=True), now_iso(), self.design_hash, __version__),
            )
        rec = self.participant(participant_id)
        assert rec is not None
        return rec

    def discard_unstarted(self, participant_id: str) -> bool:
        """Remove a participant who has no answered trial, with their sessions and plays; False (and nothing
        removed) when they have answers.

        For a session that could not start (an avatar that fails to load, a file gone missing): it must not
        leave the participant registered with 0 trials on a row they never used, in a database whose design
        is about to be fixed.
        """
        with self.transaction() as con:
            if con.execute("SELECT 1 FROM trials WHERE participant = ? LIMIT 1", (participant_id,)).fetchone():
                return False
            for table in ("plays", "questionnaire", "sessions"):
                con.execute(f"DELETE FROM {table} WHERE participant = ?", (participant_id,))
            con.execute("DELETE FROM participants WHERE id = ?", (participant_id,))
        return True

    def set_status(self, participant_id: str, status: str) -> None:
        if status not in PARTICIPANT_STATUSES:
            raise ValueError(f"unknown participant status {status!r}")
        with self.transaction(participant=participant_id) as con:
            con.execute("UPDATE participants SET status = ?, completed = CASE WHEN ? = 'active' THEN NULL ELSE ? END "
                        "WHERE id = ?", (status, status, now_iso(), participant_id))

    def update_groups(self, participant_id: str, groups: dict[str, str]) -> None:
        """Merge ``groups`` into the participant's stored groups (later values win)."""
        rec = self.participant(participant_id)
        if rec is None:
            raise KeyError(participant_id)
        merged = {**rec.groups, **groups}
        with self.transaction(participant=participant_id) as con:
            con.execute("UPDATE participants SET groups = ? WHERE id = ?", (json.dumps(merged, sort_keys=True), participant_id))

    # ------------------------------------------------------------------ sessions
    def start_session(self, participant_id: str, machine: dict[str, Any] | None = None) -> int:
        with self.transaction(participant=participant_id) as con:
            cur = con.execute(
                "INSERT INTO sessions (participant, started, app_version, design_hash, machine) VALUES (?, ?, ?, ?, ?)",
                (participant_id, now_iso(), __version__, self.design_hash, json.dumps(machine or {}, sort_keys=True)),
            )
            return int(cur.lastrowid)

    def update_session_machine(self, session_id: int, machine: dict[str, Any]) -> None:
        # read inside: another server process may write the same record (their lock: one at a time)
        with self.transaction(participant=self._owner("sessions", session_id)) as con:
            row = con.execute("SELECT machine FROM sessions WHERE id = ?", (session_id,)).fetchone()
            merged = {**(json.loads(row[0]) if row else {}), **machine}
            con.execute("UPDATE sessions SET machine = ? WHERE id = ?", (json.dumps(merged, sort_keys=True, default=str), session_id))

    def end_session(self, session_id: int) -> None:
        with self.transaction(participant=self._owner("sessions", session_id)) as con:
            con.execute("UPDATE sessions SET ended = ? WHERE id = ?", (now_iso(), session_id))

    def sessions(self, participant_id: str | None = None) -> list[dict[str, Any]]:
        q = "SELECT * FROM sessions" + (" WHERE participant = ?" if participant_id else "") + " ORDER BY id"
        rows = self._con.execute(q, (participant_id,) if participant_id else ()).fetchall()
        return [{**dict(r), "machine": json.loads(r["machine"])} for r in rows]

    # ------------------------------------------------------------------ trials and answers
    def answered_trials(self, participant_id: str) -> set[int]:
        return {r[0] for r in self._con.execute("SELECT trial_index FROM trials WHERE participant = ?", (participant_id,))}

    def trials(self, participant_id: str | None = None) -> list[dict[str, Any]]:
        q = "SELECT * FROM trials" + (" WHERE participant = ?" if participant_id else "") + " ORDER BY participant, trial_index"
        return [dict(r) for r in self._con.execute(q, (participant_id,) if participant_id else ())]

    def responses(self, participant_id: str | None = None) -> list[dict[str, Any]]:
        q = ("SELECT * FROM responses" + (" WHERE participant = ?" if participant_id else "")
             + " ORDER BY participant, trial_index, criterion, slot")
        return [dict(r) for r in self._con.execute(q, (participant_id,) if participant_id else ())]

    def trial_slots(self, participant_id: str | None = None) -> list[dict[str, Any]]:
        q = ("SELECT * FROM trial_slots" + (" WHERE participant = ?" if participant_id else "")
             + " ORDER BY participant, trial_index, slot")
        return [dict(r) for r in self._con.execute(q, (participant_id,) if participant_id else ())]

    def judgements(self, participant_id: str | None = None) -> list[dict[str, Any]]:
        q = ("SELECT * FROM judgements" + (" WHERE participant = ?" if participant_id else "")
             + " ORDER BY participant, trial_index, criterion, slot")
        return [dict(r) for r in self._con.execute(q, (participant_id,) if participant_id else ())]

    def save_trial(self, trial: TrialRecord, responses: Iterable[Response],
                   judgements: Iterable[Judgement] = ()) -> None:
        """Commit one trial, its slots and all its answers (ranks or judgements) in a single transaction
        (durable when this returns).

        Raises :class:`DuplicateAnswerError` when the trial already has an answer: answers are never
        overwritten, so a double submit (or a resumed session racing an old one) cannot change data.
        """
        from studyapp.study.schedule import three_slots

        t = trial
        left, middle, right = three_slots(t.slots)
        s_left, s_middle, s_right = three_slots(t.samples, None)
        row = {"participant": t.participant, "trial_index": t.trial_index, "session": t.session,
               "stimulus": t.stimulus, "is_practice": int(t.is_practice), "is_attention_check": int(t.is_attention_check),
               "slot_left": left, "slot_middle": middle, "slot_right": right, "shown_at": t.shown_at,
               "answered_at": t.answered_at, "response_time_s": t.response_time_s, "plays": t.plays,
               "frames_shown": t.frames_shown, "dropped_frames": t.dropped_frames, "refresh_hz": t.refresh_hz,
               "worst_av_offset_ms": t.worst_av_offset_ms,
               "attention_passed": None if t.attention_passed is None else int(t.attention_passed),
               "app_version": __version__, "trial_duration_s": t.trial_duration_s,
               "sample_left": s_left, "sample_middle": s_middle, "sample_right": s_right,
               "block": t.block, "paradigm": t.paradigm}
        motions = t.motion_stimuli or (t.stimulus,) * len(t.slots)
        slots = [{"participant": t.participant, "trial_index": t.trial_index, "slot": i, "condition": c,
                  "motion_stimulus": m, "sample": t.samples[i] if i < len(t.samples) else None,
                  "app_version": __version__} for i, (c, m) in enumerate(zip(t.slots, motions))]
        answers = [{"participant": t.participant, "trial_index": t.trial_index, "criterion": r.criterion,
                    "condition": r.condition, "slot": r.slot, "rank": float(r.rank), "app_version": __version__}
                   for r in responses]
        judged = [{"participant": t.participant, "trial_index": t.trial_index, "criterion": j.criterion,
                   "slot": j.slot, "condition": j.condition, "value": float(j.value),
                   "reasons": json.dumps(list(j.reasons), ensure_ascii=False), "app_version": __version__}
                  for j in judgements]
        with self.transaction(participant=t.participant) as con:   # "already answered": their lock, one at a time
            if con.execute("SELECT 1 FROM trials WHERE participant = ? AND trial_index = ?",
                           (t.participant, t.trial_index)).fetchone():
                raise DuplicateAnswerError(f"trial {t.trial_index} of participant {t.participant!r} is already answered")
            self._insert(con, "trials", [row])
            self._insert(con, "trial_slots", slots)
            self._insert(con, "responses", answers)
            self._insert(con, "judgements", judged)

    def _insert(self, con: sqlite3.Connection, table: str, rows: list[dict[str, Any]]) -> list[int]:
        """Insert rows of one table, every row stamped with this database's design hash; the new row ids of a
        table keyed by them (:data:`_ROW_IDS`), else none: those rows go in one statement call (one round trip
        to PostgreSQL for an answer's dozen rows, not one each)."""
        cols = _WRITTEN[table]
        sql = f"INSERT INTO {table} ({', '.join(cols)}, design_hash) VALUES ({', '.join('?' * (len(cols) + 1))})"
        if table not in _ROW_IDS:
            if rows:
                con.executemany(sql, [(*(r.get(c) for c in cols), self.design_hash) for r in rows])
            return []
        ids = []
        for r in rows:
            ids.append(int(con.execute(sql, (*(r.get(c) for c in cols), self.design_hash)).lastrowid))
        return ids

    def import_participant(self, participant: dict[str, Any], sessions: list[dict[str, Any]],
                           trials: list[dict[str, Any]], responses: list[dict[str, Any]], plays: list[dict[str, Any]],
                           questionnaire: list[dict[str, Any]], trial_slots: list[dict[str, Any]] | None = None,
                           judgements: list[dict[str, Any]] | None = None, *, replace: bool = False) -> None:
        """Add one participant recorded elsewhere (a remote participant's results file), in one transaction.

        Rows are plain dicts keyed by column name, already in this study's condition and stimulus ids; session
        ids in ``trials`` and ``plays`` are the file's own and are renumbered here. Every row gets this
        database's design hash; each keeps the app version it was recorded with. ``replace``: the participant's
        rows stored before are replaced in the same transaction (an upload that extends an earlier one; the
        caller has checked that it keeps every stored answer, :mod:`studyapp.web.uploads`).
        """
        pid = participant["id"]
        if self.participant(pid) is not None and not replace:
            raise DuplicateAnswerError(f"participant {pid!r} is already in {self.path} (duplicate: this file was "
                                       "merged before, or two participants used the same id)")
        with self.transaction() as con:
            if replace:
                for table in ("questionnaire", "plays", "judgements", "responses", "trial_slots", "trials", "sessions"):
                    con.execute(f"DELETE FROM {table} WHERE participant = ?", (pid,))
                con.execute("DELETE FROM participants WHERE id = ?", (pid,))
            self._insert(con, "participants", [participant])
            new_ids = self._insert(con, "sessions", [{**s, "participant": pid} for s in sessions])
            session_ids = {s["id"]: i for s, i in zip(sessions, new_ids)}
            self._insert(con, "trials", [{**t, "participant": pid, "session": session_ids.get(t["session"])}
                                         for t in trials])
            self._insert(con, "trial_slots", [{**r, "participant": pid} for r in trial_slots or []])
            self._insert(con, "responses", [{**r, "participant": pid} for r in responses])
            self._insert(con, "judgements", [{**r, "participant": pid} for r in judgements or []])
            self._insert(con, "plays", [{**r, "participant": pid, "session": session_ids.get(r["session"])}
                                        for r in plays])
            self._insert(con, "questionnaire", [{**q, "participant": pid, "kind": q.get("kind", "likert")}
                                                for q in questionnaire])

    def attention_failures(self, participant_id: str) -> int:
        row = self._con.execute("SELECT COUNT(*) FROM trials WHERE participant = ? AND attention_passed = 0",
                                (participant_id,)).fetchone()
        return int(row[0])

    # ------------------------------------------------------------------ plays
    def start_play(self, participant_id: str, trial_index: int, session_id: int | None) -> int:
        with self.transaction(participant=participant_id) as con:
            cur = con.execute(
                "INSERT INTO plays (participant, trial_index, session, started, design_hash, app_version) "
                "VALUES (?, ?, ?, ?, ?, ?)",
                (participant_id, trial_index, session_id, now_iso(), self.design_hash, __version__),
            )
            return int(cur.lastrowid)

    def finish_play(self, play_id: int, completed: bool) -> None:
        with self.transaction(participant=self._owner("plays", play_id)) as con:
            con.execute("UPDATE plays SET ended = ?, completed = ? WHERE id = ?", (now_iso(), int(completed), play_id))

    def play_count(self, participant_id: str, trial_index: int) -> int:
        row = self._con.execute("SELECT COUNT(*) FROM plays WHERE participant = ? AND trial_index = ?",
                                (participant_id, trial_index)).fetchone()
        return int(row[0])

    def plays(self, participant_id: str | None = None) -> list[dict[str, Any]]:
        q = "SELECT * FROM plays" + (" WHERE participant = ?" if participant_id else "") + " ORDER BY id"
        return [dict(r) for r in self._con.execute(q, (participant_id,) if participant_id else ())]

    # ------------------------------------------------------------------ questionnaire
    def save_questionnaire(self, participant_id: str, answers: dict[str, Any],
                           items: dict[str, tuple[str, str | None]] | None = None) -> None:
        """Store all answers in one transaction; ``items`` maps item id -> (kind, scale) for the record."""
        items = items or {}
        with self.transaction(participant=participant_id) as con:
            con.executemany(
                "INSERT INTO questionnaire (participant, item, kind, scale, value, design_hash, app_version) "
                "VALUES (?, ?, ?, ?, ?, ?, ?)",
                [(participant_id, k, items.get(k, ("likert", None))[0], items.get(k, ("likert", None))[1],
                  None if v is None else str(v), self.design_hash, __version__) for k, v in answers.items()],
            )

    def questionnaire(self, participant_id: str | None = None) -> list[dict[str, Any]]:
        q = ("SELECT * FROM questionnaire" + (" WHERE participant = ?" if participant_id else "")
             + " ORDER BY participant, item")
        return [dict(r) for r in self._con.execute(q, (participant_id,) if participant_id else ())]

    # ------------------------------------------------------------------ bundles
    def add_bundle_key(self, bundle_hash: str, key: dict[str, Any]) -> None:
        with self.transaction() as con:
            con.execute("INSERT OR REPLACE INTO bundles (design_hash, created, key) VALUES (?, ?, ?)",
                        (bundle_hash, now_iso(), json.dumps(key, sort_keys=True)))

    def issued_remote_ids(self) -> set[str]:
        """Participant ids handed out in the rosters of earlier bundles of this study."""
        out: set[str] = set()
        for (text,) in self._con.execute("SELECT key FROM bundles"):
            out.update(json.loads(text).get("roster", {}))
        return out

    def bundle_key(self, bundle_hash: str) -> dict[str, Any] | None:
        row = self._con.execute("SELECT key FROM bundles WHERE design_hash = ?", (bundle_hash,)).fetchone()
        return None if row is None else json.loads(row[0])

    def bundle_keys(self) -> dict[str, dict[str, Any]]:
        """Every stored bundle key, by bundle hash (completed and pending ones; see bundle.py)."""
        return {h: json.loads(text) for h, text in self._con.execute("SELECT design_hash, key FROM bundles")}

    def remove_bundle_key(self, bundle_hash: str) -> None:
        with self.transaction() as con:
            con.execute("DELETE FROM bundles WHERE design_hash = ?", (bundle_hash,))

