"""One exception type for bad input, so every layer reports problems the same way.

Every message names the file, the place in it (line, key, column) and what is wrong, because the
person who reads it is an experimenter fixing a stimulus file, not a developer reading a traceback.
"""
from __future__ import annotations

from pathlib import Path


class StudyappError(Exception):
    """Base class for errors that are shown to users as a single clear message."""


class InputError(StudyappError, ValueError):
    """A file or value given to studyapp is malformed.

    Parameters
    ----------
    path:
        The offending file (or ``None`` for in-memory data).
    where:
        The place in the file: ``"line 12"``, ``"key conditions[1].motion"``, ``"column JawOpen"``.
    problem:
        What is wrong, and where possible how to fix it.

    Examples
    --------
    >>> str(InputError("clip.bvh", "line 3", "expected OFFSET"))
    'clip.bvh, line 3: expected OFFSET'
    """

    def __init__(self, path: str | Path | None, where: str | None, problem: str) -> None:
        self.path = None if path is None else str(path)
        self.where = where
        self.problem = problem
        super().__init__(self._format())

    def _format(self) -> str:
        head = ", ".join(p for p in (self.path, self.where) if p)
        return f"{head}: {self.problem}" if head else self.problem
