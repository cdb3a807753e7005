"""Questionnaire answers: per-item summaries and Cronbach's alpha per scale."""
from __future__ import annotations

import pandas as pd


def item_summary(q: pd.DataFrame) -> pd.DataFrame:
    """Per scale and item: n, mean, sd (n-1), median, min, max of the answers.

    >>> import pandas as pd
    >>> q = pd.DataFrame({"participant": ["P1", "P2"], "item": "q1", "scale": "ease", "value": [4.0, 2.0]})
    >>> item_summary(q)[["item", "n", "mean", "sd"]].values.tolist()
    [['q1', 2, 3.0, 1.4142135623730951]]
    """
    g = q.groupby(["scale", "item"], sort=True)["value"]
    out = g.agg(n="count", mean="mean", sd="std", median="median", min="min", max="max").reset_index()
    out["n"] = out["n"].astype(int)
    return out


def cronbach_alpha(data: pd.DataFrame) -> float:
    """Cronbach's alpha of a wide frame (rows = participants, columns = items), listwise deletion.

    alpha = k/(k-1) * (1 - sum of item variances / variance of the sum score).

    >>> import pandas as pd
    >>> round(cronbach_alpha(pd.DataFrame({"a": [1, 2, 3, 4], "b": [2, 2, 3, 5], "c": [1, 3, 3, 4]})), 4)
    0.9474
    """
    x = data.dropna(axis=0, how="any").to_numpy(dtype=float)
    n, k = x.shape
    if k < 2 or n < 2:
        return float("nan")
    item_var = x.var(axis=0, ddof=1).sum()
    total_var = x.sum(axis=1).var(ddof=1)
    if total_var == 0:
        return float("nan")
    return float(k / (k - 1) * (1.0 - item_var / total_var))


def scale_reliability(q: pd.DataFrame) -> pd.DataFrame:
    """Cronbach's alpha per scale (participants with every item of the scale answered).

    Columns: scale, n_items, n_participants, alpha.
    """
    rows = []
    for scale, sub in q.groupby("scale", sort=True):
        wide = sub.pivot_table(index="participant", columns="item", values="value", aggfunc="first")
        complete = wide.dropna(axis=0, how="any")
        rows.append({"scale": scale, "n_items": int(wide.shape[1]), "n_participants": int(complete.shape[0]),
                     "alpha": cronbach_alpha(wide)})
    return pd.DataFrame(rows, columns=["scale", "n_items", "n_participants", "alpha"])
