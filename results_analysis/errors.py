"""Errors of the analysis package.

results_analysis reads only exported results and must not import studyapp, so it carries its own
input error with the same shape as studyapp's: every message names the file, the place and the problem.
"""
from __future__ import annotations

from pathlib import Path


class AnalysisInputError(ValueError):
    """Bad results input: names the file (``path``), the place (``where``: row/column/key) and the problem.

    >>> str(AnalysisInputError("results.csv", "row 12, column 'rank'", "rank 4 is outside 1..3"))
    "results.csv: row 12, column 'rank': rank 4 is outside 1..3"
    """

    def __init__(self, path: str | Path | None, where: str | None, problem: str) -> None:
        self.path = str(path) if path is not None else "<data frame>"
        self.where = where
        self.problem = problem
        parts = [self.path] + ([where] if where else []) + [problem]
        super().__init__(": ".join(parts))
