"""Where benchmarks put the figures ``run_all.py --json FILE`` collects: one JSON object per figure.

A benchmark calls :func:`record` for each headline figure; when ``run_all.py`` runs it, the environment
variable :data:`ENV` names a file (JSON lines) that ``run_all.py`` merges into its ``--json`` output.
Run on its own, a benchmark only prints. Every figure is ``{"value", "baseline", "unit"}`` plus whatever
context makes it honest (spread, load average, goal).
"""
from __future__ import annotations

import json
import os
from typing import Any

ENV = "STUDYAPP_BENCH_FIGURES"


def record(key: str, value: float, baseline: float, unit: str, **context: Any) -> None:
    """Append one figure to the file named by ``$STUDYAPP_BENCH_FIGURES`` (nothing when it is unset)."""
    path = os.environ.get(ENV)
    if not path:
        return
    row = {"key": key, "value": value, "baseline": baseline, "unit": unit, **context}
    with open(path, "a", encoding="utf-8") as f:
        f.write(json.dumps(row) + "\n")


def load_average() -> float:
    """The 1-minute load average now (every figure states it: a shared machine's figures move with it)."""
    return round(os.getloadavg()[0], 2)
