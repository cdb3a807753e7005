"""Puts ``tests/`` on ``sys.path`` so every test folder imports the shared generators as ``fixtures.<name>``.

They live here, not in ``studyapp``, because a participant's installation has no use for them (the packaging
test checks the wheel leaves them out).
"""
from __future__ import annotations

import sys
from pathlib import Path

_TESTS = str(Path(__file__).resolve().parent)
if _TESTS not in sys.path:
    sys.path.insert(0, _TESTS)


import pytest  # noqa: E402


@pytest.fixture(scope="session")
def postgres_server():
    """One throw-away PostgreSQL server for the whole test session (Debian's binaries, a temporary folder),
    stopped at the end. Missing binaries make the tests that need it fail with what to install, never skip."""
    from fixtures.postgres import TempPostgres

    server = TempPostgres(fsync=False).start()
    try:
        yield server
    finally:
        server.stop()


@pytest.fixture(params=["sqlite", "postgresql"])
def results_target(request, tmp_path):
    """A new, empty results database on each backend: an SQLite path, or the URL of a new PostgreSQL database."""
    if request.param == "sqlite":
        return tmp_path / "results.sqlite"
    import uuid

    return request.getfixturevalue("postgres_server").new_database(f"t_{uuid.uuid4().hex[:16]}")
