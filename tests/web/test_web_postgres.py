"""The browser flow's tests (test_web_flow.py), every one that runs on its ``study`` fixture, on a PostgreSQL
results database: the study server with ``--db postgresql://...`` behaves exactly as on SQLite (the server from
the ``postgres_server`` fixture, a new database per test)."""
from __future__ import annotations

import inspect
import uuid

import pytest

import test_web_flow as flow_tests  # the same folder (pytest puts it on sys.path); its tests are not collected twice
from fixtures.web_study import ClipVideos, Clock, Study

# every flow test that runs on the ``study`` fixture (the others build their own study on a file)
FLOW_TESTS = sorted(name for name in dir(flow_tests) if name.startswith("test_")
                    and list(inspect.signature(getattr(flow_tests, name)).parameters) == ["study", "browser_for"])


@pytest.fixture
def pg_study(web_study_files, postgres_server) -> Study:
    path, design = web_study_files
    url = postgres_server.new_database(f"web_{uuid.uuid4().hex[:12]}")
    return Study(path, design, url, ClipVideos(path.parent / "videos"), Clock())  # type: ignore[arg-type]


@pytest.mark.parametrize("name", FLOW_TESTS)
def test_the_browser_flow_on_postgresql(name: str, pg_study: Study, browser_for) -> None:
    db = pg_study.db()
    assert db.backend == "postgresql"
    db.close()
    getattr(flow_tests, name)(pg_study, browser_for)


def test_every_flow_test_runs_here_too() -> None:
    assert len(FLOW_TESTS) >= 11, FLOW_TESTS
