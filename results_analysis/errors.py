"""Errors of the analysis package.

results_analysis reads only exported results and must not import studyapp, so it carries its own
input error with the same shape as studyapp's: every message names the file, the place and the problem.
"""
from __future__ import annotations

import re
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


def unreadable_csv(path: str | Path, exc: Exception) -> AnalysisInputError:
    """The one-line error for a CSV file pandas cannot parse: a row with the wrong number of fields names
    its line; anything else gives pandas' reason on one line (its C parser ends some messages with a newline).

    >>> str(unreadable_csv("r.csv", ValueError("Error tokenizing data. C error: Expected 33 fields in line 41, saw 34\\n")))
    'r.csv: line 41: 34 fields where the header has 33 (a damaged or hand-edited row?)'
    """
    text = " ".join(str(exc).split())
    m = re.search(r"Expected (\d+) fields in line (\d+), saw (\d+)", text)
    if m:
        return AnalysisInputError(path, f"line {m[2]}", f"{m[3]} fields where the header has {m[1]} "
                                  "(a damaged or hand-edited row?)")
    return AnalysisInputError(path, None, f"not a readable CSV file ({text})")
