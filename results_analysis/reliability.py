"""Reliability of questionnaire scales: Cronbach's alpha with Feldt's interval, and per item the alpha if
the item is dropped and its corrected item-total (item-rest) correlation.

* alpha = k/(k-1) (1 - sum of item variances / variance of the sum score) over the participants who
  answered every item of the scale (:func:`results_analysis.questionnaire.cronbach_alpha`).
* Feldt's interval (Feldt 1965; Feldt, Woodruff & Salih 1987): (1 - alpha) / (1 - alpha_hat) follows an F
  distribution with n-1 and (n-1)(k-1) degrees of freedom, so the (1 - g) interval is
  [1 - (1 - alpha_hat) F_{1-g/2}, 1 - (1 - alpha_hat) F_{g/2}] (n participants, k items). It equals
  McGraw & Wong's (1996) interval of the consistency ICC(C,k), which alpha is.
* alpha if dropped: alpha of the other k-1 items (undefined for a two-item scale); r_drop: the Pearson
  correlation of the item with the sum of the other items.
"""
from __future__ import annotations

import numpy as np
import pandas as pd
from scipy import stats

from results_analysis.questionnaire import cronbach_alpha


def feldt_interval(alpha: float, n: int, k: int, ci: float = 0.95) -> tuple[float, float]:
    """Feldt's ``ci`` interval of Cronbach's alpha from n participants and k items.

    >>> [round(v, 3) for v in feldt_interval(0.8, 30, 5)]
    [0.659, 0.894]
    """
    if not np.isfinite(alpha) or n < 2 or k < 2:
        return float("nan"), float("nan")
    df1, df2 = n - 1, (n - 1) * (k - 1)
    g = 1.0 - ci
    return (float(1.0 - (1.0 - alpha) * stats.f.ppf(1.0 - g / 2.0, df1, df2)),
            float(1.0 - (1.0 - alpha) * stats.f.ppf(g / 2.0, df1, df2)))


def item_analysis(data: pd.DataFrame) -> pd.DataFrame:
    """Per item of a wide frame (rows = participants, columns = items; listwise deletion): alpha_if_dropped
    and r_drop (see the module docstring).

    >>> import pandas as pd
    >>> t = item_analysis(pd.DataFrame({"a": [1, 2, 3, 4], "b": [2, 2, 3, 5], "c": [1, 3, 3, 4]}))
    >>> t.round(3).values.tolist()
    [['a', 0.853, 0.981], ['b', 0.96, 0.849], ['c', 0.952, 0.851]]
    """
    wide = data.dropna(axis=0, how="any")
    rows = []
    for item in wide.columns:
        rest = wide.drop(columns=[item])
        r_drop = np.nan
        if len(wide) >= 2 and wide[item].std() > 0 and rest.sum(axis=1).std() > 0:
            r_drop = float(np.corrcoef(wide[item].to_numpy(float), rest.sum(axis=1).to_numpy(float))[0, 1])
        rows.append({"item": str(item), "alpha_if_dropped": cronbach_alpha(rest) if rest.shape[1] >= 2 else np.nan,
                     "r_drop": r_drop})
    return pd.DataFrame(rows, columns=["item", "alpha_if_dropped", "r_drop"])


def _wide(q: pd.DataFrame) -> dict[str, pd.DataFrame]:
    return {str(scale): sub.pivot_table(index="participant", columns="item", values="value", aggfunc="first")
            for scale, sub in q.groupby("scale", sort=True)}


def scale_reliability_ci(q: pd.DataFrame, *, ci: float = 0.95) -> pd.DataFrame:
    """Cronbach's alpha per scale of a long questionnaire frame (participant, item, scale, value) with Feldt's
    interval. Columns: scale, n_items, n_participants, alpha, ci_low, ci_high."""
    rows = []
    for scale, wide in _wide(q).items():
        n = int(wide.dropna(axis=0, how="any").shape[0])
        a = cronbach_alpha(wide)
        lo, hi = feldt_interval(a, n, int(wide.shape[1]), ci)
        rows.append({"scale": scale, "n_items": int(wide.shape[1]), "n_participants": n, "alpha": a,
                     "ci_low": lo, "ci_high": hi})
    return pd.DataFrame(rows, columns=["scale", "n_items", "n_participants", "alpha", "ci_low", "ci_high"])


def item_reliability(q: pd.DataFrame) -> pd.DataFrame:
    """:func:`item_analysis` for every scale of a long questionnaire frame. Columns: scale, item,
    alpha_if_dropped, r_drop."""
    parts = [item_analysis(wide).assign(scale=scale) for scale, wide in _wide(q).items()]
    cols = ["scale", "item", "alpha_if_dropped", "r_drop"]
    return pd.concat(parts, ignore_index=True)[cols] if parts else pd.DataFrame(columns=cols)
