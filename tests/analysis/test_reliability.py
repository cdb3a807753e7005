"""Cronbach's alpha with Feldt's interval, alpha if item dropped and item-rest correlations.

References:
* Shrout & Fleiss (1979), Psychol. Bull. 86(2), Table 2 (6 targets rated by 4 judges) and Table 4: mean
  squares BMS = 11.24 (between targets) and EMS = 1.02 (residual), ICC(3,k) = .91. Cronbach's alpha with
  the judges as items is ICC(3,k) = 1 - EMS/BMS (Hoyt 1941).
* McGraw & Wong (1996), Psychol. Methods 1(1), Table 7: the interval of ICC(C,k) from F_obs = BMS/EMS,
  [1 - 1/F_L, 1 - 1/F_U] with F_L = F_obs / F_{1-g/2}(n-1, (n-1)(k-1)), F_U = F_obs * F_{1-g/2}((n-1)(k-1), n-1);
  computed here from two-way ANOVA sums of squares, independently of the variance formula of alpha.
"""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from results_analysis.questionnaire import cronbach_alpha
from results_analysis.reliability import feldt_interval, item_analysis, item_reliability, scale_reliability_ci

SHROUT_FLEISS = np.array([[9, 2, 5, 8], [6, 1, 3, 2], [8, 4, 6, 8], [7, 1, 2, 6], [10, 5, 6, 9], [6, 2, 4, 7]],
                         dtype=float)


def _anova_alpha_and_interval(x: np.ndarray, ci: float) -> tuple[float, float, float, float, float]:
    n, k = x.shape
    grand = x.mean()
    ss_rows = k * np.sum((x.mean(axis=1) - grand) ** 2)
    ss_cols = n * np.sum((x.mean(axis=0) - grand) ** 2)
    ss_err = np.sum((x - grand) ** 2) - ss_rows - ss_cols
    bms, ems = ss_rows / (n - 1), ss_err / ((n - 1) * (k - 1))
    f_obs = bms / ems
    g = 1 - ci
    f_l = f_obs / stats.f.ppf(1 - g / 2, n - 1, (n - 1) * (k - 1))
    f_u = f_obs * stats.f.ppf(1 - g / 2, (n - 1) * (k - 1), n - 1)
    return 1 - ems / bms, 1 - 1 / f_l, 1 - 1 / f_u, bms, ems


def _long(x: np.ndarray, scale: str = "ease") -> pd.DataFrame:
    return pd.DataFrame([{"participant": f"P{i}", "item": f"q{j}", "scale": scale, "value": x[i, j]}
                         for i in range(x.shape[0]) for j in range(x.shape[1])])


def test_shrout_fleiss_published_mean_squares_and_icc() -> None:
    alpha_anova, lo, hi, bms, ems = _anova_alpha_and_interval(SHROUT_FLEISS, 0.95)
    assert (round(bms, 2), round(ems, 2)) == (11.24, 1.02)           # Shrout & Fleiss, Table 4
    t = scale_reliability_ci(_long(SHROUT_FLEISS))
    row = t.iloc[0]
    assert round(row["alpha"], 2) == 0.91                              # ICC(3,k) = .91
    assert row["alpha"] == pytest.approx(alpha_anova, rel=1e-12)
    assert (row["ci_low"], row["ci_high"]) == (pytest.approx(lo, rel=1e-10), pytest.approx(hi, rel=1e-10))
    assert (row["n_items"], row["n_participants"]) == (4, 6)


@pytest.mark.parametrize("seed", range(10))
def test_feldt_interval_equals_mcgraw_wong_icc_interval(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n, k = int(rng.integers(5, 80)), int(rng.integers(2, 9))
    x = rng.normal(size=(n, 1)) * rng.uniform(0, 2) + rng.normal(size=(n, k))
    ci = [0.9, 0.95, 0.99][seed % 3]
    a = cronbach_alpha(pd.DataFrame(x))
    alpha_anova, lo, hi, *_ = _anova_alpha_and_interval(x, ci)
    assert a == pytest.approx(alpha_anova, rel=1e-10, abs=1e-12)
    np.testing.assert_allclose(feldt_interval(a, n, k, ci), (lo, hi), rtol=1e-9, atol=1e-12)


def test_alpha_if_dropped_and_item_rest_correlation() -> None:
    x = pd.DataFrame(SHROUT_FLEISS, columns=["j1", "j2", "j3", "j4"])
    t = item_analysis(x).set_index("item")
    for item in x.columns:
        rest = x.drop(columns=[item])
        assert t.loc[item, "alpha_if_dropped"] == pytest.approx(_anova_alpha_and_interval(rest.to_numpy(), .95)[0])
        assert t.loc[item, "r_drop"] == pytest.approx(stats.pearsonr(x[item], rest.sum(axis=1)).statistic)
    two = item_analysis(x[["j1", "j2"]])
    assert two["alpha_if_dropped"].isna().all()  # one item left: no alpha
    q = pd.concat([_long(SHROUT_FLEISS, "a"), _long(SHROUT_FLEISS[:, :3], "b")])
    both = item_reliability(q)
    assert list(both.groupby("scale").size()) == [4, 3]
