"""``--db URL``: the one place that turns the server's database argument into a results database.

* a path, or ``sqlite:///PATH`` (``sqlite:////abs/path`` for an absolute one): SQLite, the embedded default
  (WAL, every answer fsynced: see :mod:`studyapp.study.storage`); one server process;
* ``postgresql://...`` / ``postgres://...``: PostgreSQL, for many server processes, through the PostgreSQL
  storage backend (:mod:`studyapp.study.sql_backend`): create the database (``createdb``); the tables are made on
  first use.

>>> sqlite_path("sqlite:///results/study.sqlite"), sqlite_path("sqlite:////srv/s.sqlite"), sqlite_path("a.sqlite")
('results/study.sqlite', '/srv/s.sqlite', 'a.sqlite')
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

from studyapp.errors import InputError
from studyapp.study.storage import ResultsDB
from studyapp.study.storage import open_results as storage_open_results


def sqlite_path(url: str) -> str:
    """The file of a SQLite ``--db`` value (a plain path or a ``sqlite:///`` URL)."""
    return url[len("sqlite:///"):] if url.startswith("sqlite:///") else url


def open_results(url: str | Path, design: Any) -> ResultsDB:
    """The results database ``url`` names, opened (or created) for ``design``."""
    text = str(url)
    if "://" in text and not text.startswith(("sqlite:///", "postgresql://", "postgres://")):
        raise InputError(None, "--db", f"{text.split('://')[0]}:// is not a database this server can use; give a "
                         "file path, sqlite:///PATH or postgresql://USER@HOST/DB")
    return storage_open_results(text if "://" in text else Path(text), design)
