"""``results-analysis --metrics``: the objective metrics beside the mean ranks, with exact Spearman correlations
checked against scipy (rho, and an exact permutation test) and the report's numbers against stats.json."""
from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from results_analysis.cli import main
from results_analysis.objective_metrics import compare_metrics, load_metrics, spearman_exact
from results_analysis.errors import AnalysisInputError
from results_analysis.simulate import simulate_results

CONDS = ("synced", "lagged", "static")


def _spearman_along(a, b, axis=-1):
    """Spearman's rho along ``axis`` (what scipy's permutation_test calls with a batch of orderings)."""
    ra, rb = stats.rankdata(a, axis=axis), stats.rankdata(b, axis=axis)
    ra = ra - ra.mean(axis=axis, keepdims=True)
    rb = rb - rb.mean(axis=axis, keepdims=True)
    return (ra * rb).sum(axis=axis) / np.sqrt((ra ** 2).sum(axis=axis) * (rb ** 2).sum(axis=axis))


@pytest.mark.parametrize("k", [3, 4, 5])
def test_spearman_exact_matches_scipy(k):
    rng = np.random.default_rng(k)
    for _ in range(5):
        x, y = rng.normal(size=k), rng.normal(size=k)
        x[0] = x[1]  # a tie, as two conditions with the same frozen share
        rho, p = spearman_exact(x, y)
        assert rho == pytest.approx(stats.spearmanr(x, y).statistic, abs=1e-12)
        ref = stats.permutation_test((x, y), _spearman_along, permutation_type="pairings", vectorized=True,
                                     alternative="two-sided", n_resamples=np.inf)
        assert p == pytest.approx(ref.pvalue, abs=1e-9)
    assert np.isnan(spearman_exact([1, 1, 1], [1, 2, 3])[0])


def _metrics_table() -> pd.DataFrame:
    rows = []
    for s in ("clip01", "clip02"):
        for c, (ba, jerk) in zip(CONDS, ((0.9, 230.0), (0.8, 231.0), (0.7, 14.0))):
            rows.append({"condition": c, "stimulus": s, "sample": 1, "fps": 60.0, "n_onsets": 30,
                         "beat_align": ba + (0.02 if s == "clip02" else 0.0), "jerk_m_s3": jerk})
    return pd.DataFrame(rows)


def test_report_includes_the_metrics_and_their_correlations(tmp_path, capsys):
    df = simulate_results(12, 4, conditions=CONDS, strengths=[3.0, 1.5, 1.0], seed=4)
    df.to_csv(tmp_path / "results.csv", index=False)
    _metrics_table().to_csv(tmp_path / "metrics.csv", index=False)
    assert main([str(tmp_path / "results.csv"), "--out", str(tmp_path / "out"), "--metrics",
                 str(tmp_path / "metrics.csv"), "--bootstrap", "100"]) == 0
    st = json.loads((tmp_path / "out" / "stats.json").read_text())
    obj = st["_objective_metrics"]
    assert obj["means"]["synced"]["beat_align"] == pytest.approx(0.91)
    assert set(obj["means"]["synced"]) == {"beat_align", "jerk_m_s3"}  # fps, n_onsets, sample describe rows
    for crit in ("realism", "synchronization", "diversity"):
        # the mean ranks of Table 2 (stats.json's per-condition summary)
        mean_rank = {r["condition"]: r["mean_rank"] for r in st[crit]["conditions"]}
        rec = [r for r in obj["correlations"] if r["criterion"] == crit and r["metric"] == "beat_align"][0]
        expect = stats.spearmanr([0.91, 0.81, 0.71], [mean_rank[c] for c in CONDS]).statistic
        assert rec["rho"] == pytest.approx(expect) and rec["n"] == 3
    md = (tmp_path / "out" / "report.md").read_text()
    assert "## Objective metrics" in md and "Spearman ρ" in md
    corr = pd.read_csv(tmp_path / "out" / "tables" / "metrics_rank_correlation.csv")
    assert len(corr) == 3 * 2


def test_correlation_uses_the_report_mean_ranks():
    table = _metrics_table()
    cmp = compare_metrics(table, {"realism": {"synced": 1.2, "lagged": 2.1, "static": 2.7, "other": 2.0}})
    assert cmp.missing == ["other"] and cmp.extra == []
    r = cmp.correlations.set_index("metric")
    assert r.loc["beat_align", "rho"] == pytest.approx(-1.0)  # higher beat alignment, better rank
    assert r.loc["beat_align", "p"] == pytest.approx(2 / 6)   # 2 of the 3! orderings are as extreme


def test_bad_metrics_files_are_one_line(tmp_path, capsys):
    df = simulate_results(6, 2, conditions=CONDS, seed=1)
    df.to_csv(tmp_path / "results.csv", index=False)
    (tmp_path / "m.csv").write_text("model,jerk\nsynced,1\n")
    assert main([str(tmp_path / "results.csv"), "--out", str(tmp_path / "o"), "--metrics", str(tmp_path / "m.csv")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and "m.csv" in err and "'condition'" in err and "\n" not in err
    with pytest.raises(AnalysisInputError, match="not found"):
        load_metrics(tmp_path / "missing.csv")
