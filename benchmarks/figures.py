"""One place where a benchmark records a figure for ``run_all.py --json FILE``.

A benchmark prints its own table for people and, for machines, calls :func:`record` once per headline figure::

    record("fk_ms", value=41.2, baseline=50.0, unit="ms", note="7,200 frames x 75 joints, median of 15")

``run_all.py --json FILE`` starts each benchmark with ``STUDYAPP_BENCH_JSON=FILE`` in its environment; without
it (a benchmark run on its own) ``record`` does nothing, so the scripts stay plain scripts. Each figure is
``{"value", "baseline", "unit", "ratio"}`` (``ratio`` = value / baseline, ``None`` without a baseline) plus any
extra fields given. The benchmarks run one after another, so a read-modify-write of the file is safe.
"""
from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

ENV = "STUDYAPP_BENCH_JSON"


def record(key: str, value: float, baseline: float | None, unit: str, **extra: Any) -> None:
    """Add (or replace) figure ``key`` in the JSON file named by ``$STUDYAPP_BENCH_JSON``, if set."""
    target = os.environ.get(ENV)
    if not target:
        return
    path = Path(target)
    figures = json.loads(path.read_text()) if path.exists() and path.stat().st_size else {}
    ratio = (float(value) / float(baseline)) if baseline not in (None, 0) else None
    figures[key] = {"value": float(value), "baseline": None if baseline is None else float(baseline),
                    "unit": unit, "ratio": ratio, **extra}
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(figures, indent=2, sort_keys=True) + "\n")
    os.replace(tmp, path)


def load_average() -> float:
    """The 1-minute load average now: every figure states it, since a shared machine's figures move with it."""
    return round(os.getloadavg()[0], 2)
