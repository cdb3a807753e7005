"""Fixtures of the study-server tests (the pieces themselves are in ``fixtures/web_study.py``)."""
from __future__ import annotations

from pathlib import Path
from typing import Any, Callable

import pytest

from fixtures.web_study import Browser, ClipVideos, Clock, Study, write_web_study
from studyapp.study.design import load_design


@pytest.fixture(scope="session")
def web_study_files(tmp_path_factory) -> tuple[Path, Any]:
    path = write_web_study(tmp_path_factory.mktemp("webstudy") / "study")
    return path, load_design(path)


@pytest.fixture
def study(web_study_files, tmp_path) -> Study:
    path, design = web_study_files
    return Study(path, design, tmp_path / "results.sqlite", ClipVideos(path.parent / "videos"), Clock())


@pytest.fixture
def browser_for() -> Callable[[Any, Study], Browser]:
    return Browser


@pytest.fixture
def chrome():
    from fixtures.web_serve import headless_chrome

    driver = headless_chrome()
    yield driver
    driver.quit()
