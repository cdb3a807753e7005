"""Shared reference implementations for the analysis tests (written from the published formulas)."""
from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest
from scipy import stats


def _r_wilcox_normal_p(d: np.ndarray, correct: bool = True) -> tuple[float, float]:
    """R's wilcox.test(d) normal approximation, transcribed from R's wilcox.test.default: zeros dropped,
    V = sum of ranks of positive differences, z = V - n(n+1)/4, sigma^2 = n(n+1)(2n+1)/24 - sum(t^3-t)/48
    over tied groups t, continuity correction sign(z)/2. Returns (V, two-sided p)."""
    d = np.asarray(d, dtype=float)
    d = d[d != 0]
    n = d.size
    r = stats.rankdata(np.abs(d))
    v = float(r[d > 0].sum())
    _, t = np.unique(r, return_counts=True)
    z = v - n * (n + 1) / 4
    sigma = np.sqrt(n * (n + 1) * (2 * n + 1) / 24 - (t ** 3 - t).sum() / 48)
    z = (z - (np.sign(z) * 0.5 if correct else 0.0)) / sigma
    return v, float(2 * min(stats.norm.cdf(z), stats.norm.sf(z)))


@pytest.fixture
def r_wilcox_normal_p() -> Callable[..., tuple[float, float]]:
    return _r_wilcox_normal_p
