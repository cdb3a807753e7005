"""Prove a studyapp results database intact before any of it is analysed.

``results_analysis`` imports nothing from studyapp, so this is its own implementation of the row checksums
specified in ``studyapp/study/row_checksums.py`` (canonical encoding, version 1). The checksum of one row is
the lowercase hex SHA-256 of::

    b"studyapp-row-v1" + F(table) + F(rowid) + F(name_1) + F(type_1) + F(value_1) + ... + F(name_n) + ...

``F(b)`` = 4-byte big-endian ``len(b)`` then ``b``; text is UTF-8; ``rowid`` in ASCII decimal; the columns
in ``PRAGMA table_info`` order; ``type_i`` SQLite's ``typeof()``; ``value_i`` is ``b""`` for null, ASCII
decimal for an integer, the 8-byte big-endian IEEE 754 double for a real, the stored bytes for text and blob.
Table ``row_checksums(tbl, rid, sha256)`` holds one per row of every table except ``sqlite_*`` and itself.
(``tests/study/test_row_checksums.py`` checks that this and studyapp's implementation agree.)

A database without ``row_checksums`` (written by studyapp before schema version 5) is read as it is: only
SQLite's own check proves it.
"""
from __future__ import annotations

import hashlib
import sqlite3
import struct
from pathlib import Path

from results_analysis.errors import AnalysisInputError

CHECKSUM_TABLE = "row_checksums"
_PREFIX = b"studyapp-row-v1"


def _q(name: str) -> str:
    return '"' + name.replace('"', '""') + '"'


def _s(value: object) -> str:
    return bytes(value).decode("utf-8", "replace") if isinstance(value, bytes) else str(value)


def _f(b: bytes) -> bytes:
    return len(b).to_bytes(4, "big") + b


def row_checksum(table: str, rowid: int, cells: list[tuple[str, str, object]]) -> str:
    """The checksum of one row from its ``(column name, typeof, value)`` cells (text values as bytes)."""
    out = [_PREFIX, _f(table.encode("utf-8")), _f(b"%d" % rowid)]
    for name, kind, value in cells:
        if kind == "null":
            raw = b""
        elif kind == "integer":
            raw = b"%d" % int(value)  # type: ignore[call-overload]
        elif kind == "real":
            raw = struct.pack(">d", float(value))  # type: ignore[arg-type]
        else:
            raw = bytes(value)  # type: ignore[arg-type]
        out += [_f(name.encode("utf-8")), _f(kind.encode("ascii")), _f(raw)]
    return hashlib.sha256(b"".join(out)).hexdigest()


def table_checksums(con: sqlite3.Connection, table: str) -> dict[int, str]:
    """``{rowid: checksum}`` of every row of ``table`` as stored now."""
    names = [str(r[1]) for r in con.execute(f"PRAGMA table_info({_q(table)})")]
    cols = ", ".join(f"typeof({_q(n)}), CASE WHEN typeof({_q(n)}) = 'text' THEN CAST({_q(n)} AS BLOB) "
                     f"ELSE {_q(n)} END" for n in names)
    out = {}
    for row in con.execute(f"SELECT rowid{', ' + cols if cols else ''} FROM {_q(table)}"):
        cells = [(n, str(row[1 + 2 * i]), row[2 + 2 * i]) for i, n in enumerate(names)]
        out[int(row[0])] = row_checksum(table, int(row[0]), cells)
    return out


def damaged_rows(con: sqlite3.Connection) -> list[str]:
    """``table T, rowid N: what`` for every row that does not match its stored checksum, has none, or is
    missing; [] when all match or the database has no checksums."""
    # everything read as bytes: a damaged name or checksum may not be valid UTF-8
    tables = [_s(r[0]) for r in con.execute("SELECT CAST(name AS BLOB) FROM sqlite_master WHERE type = 'table'")]
    if CHECKSUM_TABLE not in tables:
        return []
    stored: dict[str, dict[int, str]] = {}
    for table, rid, digest in con.execute(f"SELECT CAST(tbl AS BLOB), rid, CAST(sha256 AS BLOB) FROM {CHECKSUM_TABLE}"):
        stored.setdefault(_s(table), {})[rid if isinstance(rid, int) else -1] = _s(digest)
    problems = []
    for table in sorted(t for t in tables if not t.startswith("sqlite_") and t != CHECKSUM_TABLE):
        want = stored.pop(table, {})
        for rid, got in table_checksums(con, table).items():
            expected = want.pop(rid, None)
            if expected != got:
                what = "has no checksum" if expected is None else "does not match its checksum"
                problems.append(f"table {table}, rowid {rid}: the row {what}")
        problems += [f"table {table}, rowid {rid}: the row is missing" for rid in want]
    problems += [f"table {t!r}: checksums of a table that is not in the file" for t in stored]
    return problems


def verify_database(con: sqlite3.Connection, path: str | Path) -> None:
    """Raise :class:`AnalysisInputError` unless SQLite's ``PRAGMA integrity_check`` (a superset of
    ``quick_check`` that also compares every index with its table) passes and every row matches its checksum.
    """
    try:
        report = [str(r[0]) for r in con.execute("PRAGMA integrity_check").fetchall()]
        problems = [] if report == ["ok"] else [ln.strip() for r in report for ln in r.splitlines()
                                                if ln.strip() and not ln.startswith("*** in database")]
        if not problems:
            problems = damaged_rows(con)
    except (sqlite3.DatabaseError, UnicodeDecodeError) as exc:
        problems = [f"cannot be read ({exc})"]
    if problems:
        shown = "; ".join(problems[:3]) + (f" (+{len(problems) - 3} more)" if len(problems) > 3 else "")
        raise AnalysisInputError(path, "integrity", f"the results database is damaged: {shown}. Nothing was "
                                 "analysed; restore the file from a backup")
