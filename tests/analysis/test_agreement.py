"""Inter-rater agreement per stimulus (Kendall's W across participants), checked against:
* ProofWiki, "Kendall's Coefficient of Concordance/Examples/Arbitrary Example 1": 4 judges rank 3
  competitors (X: 1,1,2,3; Y: 3,2,3,1; Z: 2,3,1,2), W = 1/16;
* Kendall's tie-corrected formula W = 12 S / (m^2 (k^3 - k) - m sum T) written here from the definition,
  and scipy.stats.friedmanchisquare for chi2 = m (k-1) W.
"""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from results_analysis.adjust import adjust_pvalues
from results_analysis.agreement import agreement_summary, stimulus_agreement


def _tidy(ranks: dict[str, list[float]], stimulus: str = "s1", criterion: str = "realism",
          offset: int = 0) -> pd.DataFrame:
    rows = []
    for r, (judge, vals) in enumerate(ranks.items()):
        for cond, v in zip("XYZ", vals):
            rows.append({"participant": judge, "trial_index": offset + r, "stimulus": stimulus,
                         "criterion": criterion, "condition": cond, "rank": v})
    return pd.DataFrame(rows)


def test_proofwiki_example_w_one_sixteenth() -> None:
    df = _tidy({"A": [1, 3, 2], "B": [1, 2, 3], "C": [2, 3, 1], "D": [3, 1, 2]})
    t = stimulus_agreement(df, conditions=list("XYZ"), criteria=["realism"])
    row = t.iloc[0]
    assert row["n_raters"] == 4 and row["kendall_w"] == pytest.approx(1 / 16)
    assert row["chi2"] == pytest.approx(4 * 2 / 16) and row["p"] == pytest.approx(stats.chi2.sf(0.5, 2))


def _kendall_w_by_hand(r: np.ndarray) -> float:
    m, k = r.shape
    s = float(np.sum((r.sum(axis=0) - m * (k + 1) / 2) ** 2))
    ties = sum(float(np.sum(c ** 3 - c)) for c in (np.unique(row, return_counts=True)[1] for row in r))
    return 12 * s / (m ** 2 * (k ** 3 - k) - m * ties)


def test_per_stimulus_w_with_ties_and_adjusted_p_match_hand_formula_and_scipy() -> None:
    rng = np.random.default_rng(3)
    frames, expected = [], {}
    for s in range(6):
        m = int(rng.integers(3, 12))
        # ties written 1,1,3 in some answers: the raw codes, ranked within the trial by the analysis
        raw = np.array([rng.choice([[1, 2, 3], [1, 1, 3], [2, 1, 3], [3, 2, 1], [1, 3, 2], [2, 2, 1]])
                        for _ in range(m)], dtype=float)
        frames.append(_tidy({f"P{j}": list(raw[j]) for j in range(m)}, stimulus=f"clip{s}", offset=100 * s))
        r = stats.rankdata(raw, axis=1)
        chi2 = stats.friedmanchisquare(*r.T).statistic if np.ptp(r, axis=1).any() else 0.0
        expected[f"clip{s}"] = (m, _kendall_w_by_hand(r), chi2, stats.chi2.sf(chi2, 2))
    t = stimulus_agreement(pd.concat(frames, ignore_index=True), conditions=list("XYZ"), criteria=["realism"],
                           adjust="bh")
    for row in t.itertuples():
        m, w, chi2, p = expected[row.stimulus]
        assert (row.n_raters, row.df) == (m, 2)
        assert row.kendall_w == pytest.approx(w, rel=1e-12)
        assert row.chi2 == pytest.approx(chi2, rel=1e-12) and row.chi2 == pytest.approx(m * 2 * w, rel=1e-12)
        assert row.p == pytest.approx(p, rel=1e-12)
    np.testing.assert_allclose(t["p_adjusted"], stats.false_discovery_control(t["p"], method="bh"))
    summary = agreement_summary(t).iloc[0]
    assert summary["n_stimuli"] == 6 and summary["median_w"] == pytest.approx(np.median(t["kendall_w"]))
    assert summary["n_significant"] == int((adjust_pvalues(t["p"], "bh") < 0.05).sum())


def test_a_stimulus_with_one_rater_has_no_w_and_repeats_are_averaged() -> None:
    one = _tidy({"A": [1, 2, 3]}, stimulus="lonely")
    twice = pd.concat([_tidy({"A": [1, 2, 3], "B": [1, 2, 3]}, stimulus="rep"),
                       _tidy({"A": [3, 2, 1]}, stimulus="rep", offset=10)])  # A ranked it twice
    t = stimulus_agreement(pd.concat([one, twice]), conditions=list("XYZ"), criteria=["realism"])
    lonely = t[t["stimulus"] == "lonely"].iloc[0]
    assert lonely["n_raters"] == 1 and np.isnan(lonely["kendall_w"])
    rep = t[t["stimulus"] == "rep"].iloc[0]
    # A's mean ranks (2, 2, 2) tie every condition; B gives (1, 2, 3): W by hand
    assert rep["n_raters"] == 2
    assert rep["kendall_w"] == pytest.approx(_kendall_w_by_hand(np.array([[2.0, 2, 2], [1, 2, 3]])))
