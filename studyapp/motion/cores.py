"""How many threads the motion code's numpy work is split over: one per core this process may use (its CPU
affinity, not the machine's count: a container or ``taskset`` may allow fewer), at most ``limit`` (past a
few, memory bandwidth, not arithmetic, bounds these loops).

>>> 1 <= usable_cores(4) <= 4
True
"""
from __future__ import annotations

import os


def usable_cores(limit: int) -> int:
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        cores = os.cpu_count() or 1
    return max(1, min(cores, limit))
