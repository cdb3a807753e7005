"""Per-row checksums of a results database: every column of every row, sealed in the row's own transaction.

SQLite's own checks (``PRAGMA integrity_check``) prove the file's structure, not its contents: a flipped bit
inside a text or number leaves a valid file with a different value (``clip04`` read back as ``clkp04``).
So every row of every table carries a SHA-256 of all its columns in table ``row_checksums``, written by
:class:`~studyapp.study.storage.ResultsDB` in the same transaction as the row, and verified whenever a
database is opened (the session, ``export``, ``merge``, ``bundle``) and by ``results_analysis``.

Canonical encoding, version 1 (``results_analysis.integrity`` implements it independently, because
``results_analysis`` imports nothing from studyapp; ``tests/study/test_row_checksums.py`` checks that both
agree). The checksum of one row is the lowercase hex SHA-256 of::

    b"studyapp-row-v1" + F(table) + F(rowid) + F(name_1) + F(type_1) + F(value_1) + ... + F(name_n) + ...

- ``F(b)`` is ``len(b)`` as a 4-byte big-endian unsigned integer followed by ``b``; text is UTF-8;
- ``table`` is the table's name, ``rowid`` its SQLite rowid in ASCII decimal;
- columns 1..n are all the table's columns in ``PRAGMA table_info`` order (a column added later is
  covered with no change here), ``name_i`` the column's name, ``type_i`` SQLite's ``typeof()`` of the
  stored value (``null``, ``integer``, ``real``, ``text``, ``blob``);
- ``value_i`` is ``b""`` for null, the ASCII decimal for an integer, the 8-byte big-endian IEEE 754
  double for a real, the stored bytes as they are (never decoded) for text and blob.

``row_checksums(tbl, rid, sha256)`` holds one row per row of every other table (tables named ``sqlite_*``
are SQLite's own). A row whose checksum differs, a row without a checksum (written by another program) and
a checksum without its row (a row lost) are each reported, naming the table and the row's key.

On PostgreSQL (:class:`~studyapp.study.sql_backend.PgConnection`) the encoding is the same, with ``rowid``
the ``rowid`` column every table has there, and ``type_i`` the SQLite type the value would have: ``null``
for NULL, ``integer`` for an integer column, ``real`` for a double, ``text`` (UTF-8 bytes) for text,
``blob`` for bytes. The changed rows come from permanent row triggers into
``sql_backend.PG_DIRTY_TABLE``, keyed by the writing transaction's id (temporary triggers do not exist there).
"""
from __future__ import annotations

import hashlib
import sqlite3
import struct
from typing import Callable, Iterable, Iterator

#: The table holding the checksums (its own rows are not checksummed: a damaged one shows as a mismatch).
TABLE = "row_checksums"
CREATE_TABLE = (f"CREATE TABLE {TABLE} (tbl TEXT NOT NULL, rid INTEGER NOT NULL, sha256 TEXT NOT NULL, "
                "PRIMARY KEY (tbl, rid)) WITHOUT ROWID")
_PREFIX = b"studyapp-row-v1"
#: Temporary (per-connection) table of the rows a transaction touched; sealed and emptied at commit.
_DIRTY = "temp._studyapp_dirty_rows"
#: Rows read per statement when sealing (under SQLite's default limit of 999 parameters).
_SEAL_CHUNK = 500


def _is_sqlite(con: object) -> bool:
    return isinstance(con, sqlite3.Connection)


def _field(b: bytes) -> bytes:
    return struct.pack(">I", len(b)) + b


def _value_bytes(kind: str, value: object) -> bytes:
    if kind == "null":
        return b""
    if kind == "integer":
        return str(int(value)).encode("ascii")  # type: ignore[call-overload]
    if kind == "real":
        return struct.pack(">d", float(value))  # type: ignore[arg-type]
    return bytes(value)  # type: ignore[arg-type]  # text (read as its stored bytes) and blob


def _text(value: object) -> str:
    return bytes(value).decode("utf-8", "replace") if isinstance(value, bytes) else str(value)


def _int(value: object) -> int:
    return value if isinstance(value, int) else -1  # a damaged rowid (stored as another type) matches no row


def covered_tables(con: sqlite3.Connection) -> list[str]:
    """Every table whose rows carry a checksum: all but SQLite's own and the checksum table."""
    names = [_text(r[0]) for r in con.execute("SELECT CAST(name AS BLOB) FROM sqlite_master WHERE type = 'table' "
                                               "ORDER BY name")]
    return [n for n in names if not n.startswith("sqlite_") and n != TABLE]


def _quote(name: str) -> str:
    return '"' + name.replace('"', '""') + '"'


def _columns(con: sqlite3.Connection, table: str) -> list[str]:
    return [str(r[1]) for r in con.execute(f"PRAGMA table_info({_quote(table)})")]


def _select(table: str, columns: list[str], where: str = "") -> str:
    # typeof() tells the stored type; text is read back as its bytes so a damaged (non-UTF-8) text still hashes
    parts = [f"typeof({_quote(c)}), CASE typeof({_quote(c)}) WHEN 'text' THEN CAST({_quote(c)} AS BLOB) "
             f"ELSE {_quote(c)} END" for c in columns]
    return f"SELECT rowid, {', '.join(parts)} FROM {_quote(table)}{where}"


_KINDS = {k: _field(k.encode("ascii")) for k in ("null", "integer", "real", "text", "blob")}


def _digester(table: str, columns: list[str]) -> Callable[[tuple], str]:
    """The checksum function of one table's rows (as :func:`_select` reads them); the parts that are the same
    for every row (prefix, table, column names) are encoded once."""
    head = _PREFIX + _field(table.encode("utf-8"))
    names = [_field(c.encode("utf-8")) for c in columns]

    def digest(row: tuple) -> str:
        parts = [head, _field(str(int(row[0])).encode("ascii"))]
        for i, name in enumerate(names):
            kind = str(row[1 + 2 * i])
            parts += (name, _KINDS.get(kind) or _field(kind.encode("ascii")),
                      _field(_value_bytes(kind, row[2 + 2 * i])))
        return hashlib.sha256(b"".join(parts)).hexdigest()
    return digest


def _typed(value: object) -> tuple[str, object]:
    """A PostgreSQL value as (SQLite storage class, value as :func:`_value_bytes` reads it)."""
    if value is None:
        return "null", None
    if isinstance(value, (bool, int)):
        return "integer", int(value)
    if isinstance(value, float):
        return "real", value
    if isinstance(value, str):
        return "text", value.encode("utf-8")
    return "blob", bytes(value)  # type: ignore[call-overload]


def _read(con: sqlite3.Connection, table: str, columns: list[str], where: str = "",
          params: tuple = ()) -> Iterator[tuple]:
    """Rows as ``(rowid, type_1, value_1, ...)`` (what :func:`_digester` reads), on either engine."""
    if _is_sqlite(con):
        yield from con.execute(_select(table, columns, where), params)
        return
    cols = ", ".join(_quote(c) for c in columns)
    for row in con.execute(f"SELECT rowid{', ' if cols else ''}{cols} FROM {_quote(table)}{where}", params):
        out: list[object] = [row[0]]
        for v in tuple(row)[1:]:
            out += _typed(v)
        yield tuple(out)


def row_digests(con: sqlite3.Connection, table: str) -> Iterator[tuple[int, str]]:
    """``(rowid, checksum)`` of every row of ``table`` as it is stored now."""
    columns = _columns(con, table)
    digest = _digester(table, columns)
    for row in _read(con, table, columns):
        yield int(row[0]), digest(row)


# ------------------------------------------------------------------ writing
def prepare(con: sqlite3.Connection) -> None:
    """Make the connection's (temporary, never stored) list of changed rows; call once, right after opening.

    ``recursive_triggers`` makes ``INSERT OR REPLACE`` report the row it replaces to the delete trigger.
    """
    if not _is_sqlite(con):
        return  # PostgreSQL: a permanent table, made with the first table (sql_backend)
    con.execute("PRAGMA recursive_triggers = ON")
    con.execute(f"CREATE TABLE IF NOT EXISTS {_DIRTY} (tbl TEXT NOT NULL, rid INTEGER NOT NULL, "
                "PRIMARY KEY (tbl, rid))")


def install_triggers(con: sqlite3.Connection) -> None:
    """Record every row this connection inserts, updates or deletes, so :func:`seal_dirty` can seal it.

    Temporary triggers (this connection only, nothing stored in the file), made from the tables as they are
    when the database is opened (after any migration), so a table or column added later is covered.
    PostgreSQL has no temporary triggers: there each table gets its trigger when it is created (sql_backend).
    """
    if not _is_sqlite(con):
        return
    for table in covered_tables(con):
        lit = "'" + table.replace("'", "''") + "'"
        for event, refs in (("INSERT", ("NEW",)), ("UPDATE", ("OLD", "NEW")), ("DELETE", ("OLD",))):
            name = _quote(f"_studyapp_dirty_{event.lower()}_{table}")
            body = " ".join(f"INSERT OR IGNORE INTO {_DIRTY.split('.')[1]} VALUES ({lit}, {ref}.rowid);" for ref in refs)
            con.execute(f"CREATE TEMP TRIGGER IF NOT EXISTS {name} AFTER {event} ON main.{_quote(table)} "
                        f"BEGIN {body} END")


def _seal(con: sqlite3.Connection, table: str, rids: Iterable[int]) -> None:
    columns = _columns(con, table)
    if not _is_sqlite(con):
        _seal_together(con, table, columns, list(rids))
        return
    # one read per _SEAL_CHUNK rows (not one per row): a group commit seals hundreds at once
    digest = _digester(table, columns)
    rids = list(rids)
    found: dict[int, str] = {}
    for k in range(0, len(rids), _SEAL_CHUNK):
        chunk = tuple(rids[k:k + _SEAL_CHUNK])
        found.update((int(r[0]), digest(r)) for r in _read(con, table, columns,
                                                            f" WHERE rowid IN ({', '.join('?' * len(chunk))})", chunk))
    gone = [rid for rid in rids if rid not in found]
    if gone:
        con.executemany(f"DELETE FROM {TABLE} WHERE tbl = ? AND rid = ?", [(table, rid) for rid in gone])
    if found:
        con.executemany(f"INSERT OR REPLACE INTO {TABLE} (tbl, rid, sha256) VALUES (?, ?, ?)",
                        [(table, rid, d) for rid, d in found.items()])


def _seal_together(con: sqlite3.Connection, table: str, columns: list[str], rids: list[int]) -> None:
    """:func:`_seal` in three statements whatever the number of rows (a server is a round trip away)."""
    digest = _digester(table, columns)
    found = {int(r[0]): digest(r) for r in _read(con, table, columns, " WHERE rowid = ANY(?)", (rids,))}
    gone = [rid for rid in rids if rid not in found]
    if gone:
        con.execute(f"DELETE FROM {TABLE} WHERE tbl = ? AND rid = ANY(?)", (table, gone))
    if found:
        con.executemany(f"INSERT OR REPLACE INTO {TABLE} (tbl, rid, sha256) VALUES (?, ?, ?)",
                        [(table, rid, d) for rid, d in found.items()])


def seal_dirty(con: sqlite3.Connection) -> None:
    """Write the checksums of the rows changed in the open transaction (call just before COMMIT)."""
    dirty: dict[str, list[int]] = {}
    if _is_sqlite(con):
        listed, clear = f"SELECT tbl, rid FROM {_DIRTY}", f"DELETE FROM {_DIRTY}"
    else:
        from studyapp.study.sql_backend import PG_DIRTY_TABLE

        mine = " WHERE xid = txid_current()"  # this transaction's rows only: another program's stay unsealed
        listed, clear = f"SELECT DISTINCT tbl, rid FROM {PG_DIRTY_TABLE}{mine}", f"DELETE FROM {PG_DIRTY_TABLE}{mine}"
    for table, rid in con.execute(listed):
        dirty.setdefault(table, []).append(rid)
    for table, rids in dirty.items():
        _seal(con, table, rids)
    if dirty:
        con.execute(clear)


def seal_all(con: sqlite3.Connection) -> None:
    """(Re)write the checksum of every row (a new database, or a migration that changed the tables)."""
    con.execute(f"DELETE FROM {TABLE}")
    for table in covered_tables(con):
        con.executemany(f"INSERT INTO {TABLE} (tbl, rid, sha256) VALUES (?, ?, ?)",
                        [(table, rid, digest) for rid, digest in row_digests(con, table)])


# ------------------------------------------------------------------ checking
def _key_text(con: sqlite3.Connection, table: str, rid: int) -> str:
    """The row's primary key as ``col 'value'`` pairs (its rowid when the table has none, or it is unreadable)."""
    pk = sorted((int(r[5]), str(r[1])) for r in con.execute(f"PRAGMA table_info({_quote(table)})") if r[5])
    if not pk:
        return f"rowid {rid}"
    cols = [c for _, c in pk]
    try:
        row = next(_read(con, table, cols, " WHERE rowid = ?", (rid,)), None)
    except sqlite3.Error:
        row = None
    if row is None:
        return f"rowid {rid}"
    shown = []
    for i, c in enumerate(cols):
        v = row[2 + 2 * i]
        shown.append(f"{c} {bytes(v).decode('utf-8', 'replace')!r}" if isinstance(v, bytes) else f"{c} {v}")
    return ", ".join(shown)


def verify(con: sqlite3.Connection) -> list[str]:
    """Every row that does not match its checksum, one ``table T, row KEY: what`` line each ([] when all match).

    Raises :class:`sqlite3.Error` when a table cannot be read at all (the caller reports the file as damaged).
    """
    problems: list[str] = []
    stored: dict[str, dict[int, str]] = {}
    # read as bytes: a damaged checksum row may not even be valid UTF-8
    for table, rid, digest in con.execute(f"SELECT CAST(tbl AS BLOB), rid, CAST(sha256 AS BLOB) FROM {TABLE}"):
        stored.setdefault(_text(table), {})[_int(rid)] = _text(digest)
    tables = covered_tables(con)
    for table in tables:
        expected = stored.pop(table, {})
        for rid, digest in row_digests(con, table):
            want = expected.pop(rid, None)
            if want is None:
                problems.append(f"table {table}, row {_key_text(con, table, rid)}: the row has no checksum "
                                "(damaged, or written by another program)")
            elif want != digest:
                problems.append(f"table {table}, row {_key_text(con, table, rid)}: the row does not match its "
                                "checksum (damaged, or edited by another program)")
        problems += [f"table {table}, rowid {rid}: a row is missing (its checksum is there)" for rid in expected]
    for table, rows in stored.items():
        problems.append(f"table {table!r}: {len(rows)} checksum(s) of a table that is not in the file")
    return problems
