"""p-value adjustments (Holm, Benjamini-Hochberg, Bonferroni) and comparisons against a control.

References checked:
* Benjamini & Hochberg (1995), J. R. Stat. Soc. B 57(1), 289-300, section 4: the 15 p-values of the
  myocardial-infarction study; at q = 0.05 their procedure rejects the four smallest, the Bonferroni
  procedure the three with p <= 0.0033.
* scipy.stats.false_discovery_control (an independent implementation of BH).
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from results_analysis.adjust import adjust_pvalues
from results_analysis.posthoc import conover, wilcoxon_holm

BH_1995 = [0.0201, 0.7590, 0.0001, 0.3240, 0.0004, 0.0278, 0.0459, 0.0019, 0.4262, 0.0095, 0.0298, 0.5719,
           0.0344, 0.6528, 1.0000]


def test_bh_paper_example_rejects_four_and_bonferroni_three() -> None:
    p = np.array(BH_1995)
    bh = adjust_pvalues(p, "bh")
    assert sorted(p[bh <= 0.05].tolist()) == [0.0001, 0.0004, 0.0019, 0.0095]
    assert sorted(p[adjust_pvalues(p, "bonferroni") <= 0.05].tolist()) == [0.0001, 0.0004, 0.0019]
    # Holm is uniformly at least as powerful as Bonferroni, here also three.
    assert sorted(p[adjust_pvalues(p, "holm") <= 0.05].tolist()) == [0.0001, 0.0004, 0.0019]


def _hand_holm(p: np.ndarray) -> np.ndarray:
    m = len(p)
    order = np.argsort(p)
    out = np.empty(m)
    running = 0.0
    for rank, i in enumerate(order):
        running = max(running, min(1.0, (m - rank) * p[i]))
        out[i] = running
    return out


@pytest.mark.parametrize("seed", range(20))
def test_adjustments_match_scipy_and_hand_formulas(seed: int) -> None:
    rng = np.random.default_rng(seed)
    p = rng.uniform(0, 1, rng.integers(1, 30)) ** rng.uniform(0.5, 4)
    if seed % 3 == 0:
        p[: len(p) // 2] = p[0]  # ties among the p-values
    np.testing.assert_allclose(adjust_pvalues(p, "bh"), stats.false_discovery_control(p, method="bh"),
                               rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(adjust_pvalues(p, "holm"), _hand_holm(p), rtol=1e-12)
    np.testing.assert_allclose(adjust_pvalues(p, "bonferroni"), np.minimum(1, p * len(p)), rtol=1e-12)


def test_unknown_adjustment_is_refused() -> None:
    with pytest.raises(ValueError, match="holm, bh, bonferroni"):
        adjust_pvalues([0.1], "sidak")


def _values(seed: int, n: int = 15, k: int = 4) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.argsort(np.argsort(rng.normal(size=(n, k)) + np.arange(k) * 0.6, axis=1), axis=1) + 1.0


def test_control_runs_only_k_minus_1_pairs_adjusted_over_k_minus_1() -> None:
    v = _values(4)
    names = ["ours", "b1", "b2", "b3"]
    full = wilcoxon_holm(v, names, adjust="bonferroni")
    ctl = wilcoxon_holm(v, names, adjust="bonferroni", control="b2")
    assert [(r.a, r.b) for r in ctl.itertuples()] == [("b2", "ours"), ("b2", "b1"), ("b2", "b3")]
    for r in ctl.itertuples():
        d = v[:, names.index(r.a)] - v[:, names.index(r.b)]
        d = d[d != 0]
        p = stats.wilcoxon(d, correction=True, method="asymptotic").pvalue
        assert r.p == pytest.approx(p, rel=1e-12)
        assert r.p_adjusted == pytest.approx(min(1.0, 3 * p), rel=1e-12)  # over k-1 = 3, not 6
    assert (ctl["adjustment"] == "Bonferroni").all() and len(full) == 6
    con = conover(v, names, adjust="bh", control="ours")
    assert list(con["b"]) == ["b1", "b2", "b3"]
    np.testing.assert_allclose(con["p_adjusted"], stats.false_discovery_control(con["p"], method="bh"))
    with pytest.raises(KeyError, match="control condition 'nope'"):
        wilcoxon_holm(v, names, control="nope")


def test_float_noise_in_mean_ranks_neither_breaks_ties_nor_hides_zeros() -> None:
    # 0.1 + 0.2 != 0.3 in floating point; participants' mean ranks carry such noise
    noisy = np.array([0.1 + 0.2, 0.3, 0.5, -0.7, 1.1, 0.9, (0.1 + 0.2) - 0.3])
    clean = np.array([0.3, 0.3, 0.5, -0.7, 1.1, 0.9, 0.0])
    got = wilcoxon_holm(np.c_[noisy, np.zeros(7)], ["a", "b"]).iloc[0]
    ref = wilcoxon_holm(np.c_[clean, np.zeros(7)], ["a", "b"]).iloc[0]
    assert got["method"] == ref["method"] == "normal approximation"  # a tie and a zero: no exact test
    assert (got["statistic"], got["p"], got["zeros_dropped"]) == (ref["statistic"], ref["p"], 1)
