"""One small thread pool for the motion layer's big batched jobs.

numpy's ufuncs (``sin``/``cos`` above all, which run at libm speed in float64) release the GIL, so
cutting a long recording in two lets a second core do half of its Euler conversion. Small inputs (the viewer's per-frame calls) never touch the pool.
"""
from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor

import numpy as np

_POOL: ThreadPoolExecutor | None = None
WORKERS = 2


def pool() -> ThreadPoolExecutor:
    global _POOL
    if _POOL is None:
        _POOL = ThreadPoolExecutor(max_workers=WORKERS, thread_name_prefix="studyapp-motion")
    return _POOL


def map_rows(fn: Callable[[np.ndarray], np.ndarray], a: np.ndarray, min_rows: int = 2048) -> np.ndarray:
    """``fn(a)`` computed on halves of ``a``'s first axis in parallel when ``a`` is long.

    ``fn`` must work row by row (the result for a row depends on that row only), so the halves
    concatenate to exactly what one call gives.
    """
    n = a.shape[0]
    if n < min_rows:
        return fn(a)
    cuts = [n * k // WORKERS for k in range(WORKERS + 1)]
    parts = list(pool().map(lambda k: fn(a[cuts[k] : cuts[k + 1]]), range(WORKERS)))
    return np.concatenate(parts)
