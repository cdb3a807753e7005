"""Multiple-comparison adjustment of a family of p-values: one place for every post-hoc table.

* ``holm`` (default): Holm's (1979) step-down procedure, family-wise error rate. Sorted p_(1) <= ... <= p_(m),
  adjusted p_(i) = max_{j <= i} min(1, (m - j + 1) p_(j)).
* ``bh``: Benjamini & Hochberg's (1995) step-up procedure, false discovery rate (independent or positively
  dependent tests). Adjusted p_(i) = min_{j >= i} min(1, m p_(j) / j).
* ``bonferroni``: min(1, m p), family-wise error rate (single step).

Every function returns the adjusted values in the input order; a hypothesis is rejected at level alpha when
its adjusted p-value is <= alpha (R's ``p.adjust`` conventions; ``bh`` equals scipy's
``false_discovery_control(method='bh')``).
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np

#: The adjustments a user may choose, by their command-line name.
ADJUSTMENTS = ("holm", "bh", "bonferroni")

#: How each adjustment is named in the method text and the tables.
ADJUSTMENT_NAMES = {"holm": "Holm", "bh": "Benjamini–Hochberg", "bonferroni": "Bonferroni"}

#: What each adjustment controls, for the method text.
ADJUSTMENT_CONTROLS = {"holm": "family-wise error rate", "bh": "false discovery rate",
                       "bonferroni": "family-wise error rate"}


def adjust_pvalues(p: Sequence[float] | np.ndarray, method: str = "holm") -> np.ndarray:
    """Adjusted p-values of one family, in the input order (see the module docstring).

    >>> adjust_pvalues([0.01, 0.04, 0.03], "holm").round(3).tolist()
    [0.03, 0.06, 0.06]
    >>> adjust_pvalues([0.01, 0.04, 0.03], "bh").round(3).tolist()
    [0.03, 0.04, 0.04]
    >>> adjust_pvalues([0.01, 0.04, 0.03], "bonferroni").round(3).tolist()
    [0.03, 0.12, 0.09]
    """
    if method not in ADJUSTMENTS:
        raise ValueError(f"unknown p-value adjustment {method!r}: one of {', '.join(ADJUSTMENTS)}")
    p = np.asarray(p, dtype=float)
    m = p.size
    if m == 0:
        return p.copy()
    if np.any((p < 0) | (p > 1)):
        raise ValueError("p-values must lie in [0, 1]")
    if method == "bonferroni":
        return np.minimum(1.0, p * m)
    order = np.argsort(p, kind="stable")
    ps = p[order]
    if method == "holm":
        adj = np.maximum.accumulate(ps * (m - np.arange(m)))
    else:  # bh: the running minimum from the largest p downwards
        adj = np.minimum.accumulate((ps * m / np.arange(1, m + 1))[::-1])[::-1]
    out = np.empty(m)
    out[order] = np.minimum(1.0, adj)
    return out
