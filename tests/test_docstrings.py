"""The docstring examples of both packages run as tests: they are the API's documentation and must stay true.
So do those of the tests' shared generators (``tests/fixtures``), which the tests and benchmarks rely on.

Run here (not with ``--doctest-modules``) so the test folders' several ``conftest.py`` files are never
collected as modules of the same name.
"""
from __future__ import annotations

import doctest
import importlib
import pkgutil

import pytest

import results_analysis
import studyapp

import fixtures  # tests/fixtures, on sys.path through tests/conftest.py


def _modules() -> list[str]:
    """Every module of both packages that has docstring examples (a module without any has nothing to test)."""
    names = [studyapp.__name__, results_analysis.__name__]
    for pkg in (studyapp, results_analysis):
        names += [i.name for i in pkgutil.walk_packages(pkg.__path__, prefix=pkg.__name__ + ".")
                  if not i.name.endswith("__main__")]
    finder = doctest.DocTestFinder()
    names += [f"fixtures.{i.name}" for i in pkgutil.iter_modules(fixtures.__path__)]  # the tests' own generators
    return sorted(n for n in names if any(t.examples for t in finder.find(importlib.import_module(n))))


@pytest.mark.parametrize("name", _modules())
def test_docstring_examples(name: str) -> None:
    module = importlib.import_module(name)
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE, verbose=False)
    assert result.failed == 0, f"{result.failed} of {result.attempted} docstring examples failed in {name}"
