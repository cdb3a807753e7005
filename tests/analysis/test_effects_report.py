"""The effect-size intervals, adjustment, control, agreement and reliability as the report, stats.json, the
tables and the command line carry them: each number equals an independent call of the function that
computes it, and the choices are stated in the method text and the tables."""
from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from results_analysis.agreement import stimulus_agreement
from results_analysis.cli import main
from results_analysis.effect_sizes import effect_sizes
from results_analysis.ranks import rank_blocks
from results_analysis.reliability import feldt_interval
from results_analysis.report import analyze
from results_analysis.simulate import simulate_results

CONDS = ["CaMN", "DiffSHEG", "FaceCapGes"]


def _questionnaire(df: pd.DataFrame) -> pd.DataFrame:
    rng = np.random.default_rng(1)
    rows = []
    for p in sorted(df["participant"].unique()):
        base = rng.normal()
        rows += [{"participant": p, "item": f"q{i}", "scale": "ease", "value": float(round(3 + base + rng.normal()))}
                 for i in range(4)]
    return pd.DataFrame(rows)


def test_control_and_adjustment_reach_stats_tables_and_text(tmp_path) -> None:
    df = simulate_results(12, 3, seed=4)
    q = _questionnaire(df)
    a = analyze(df, tmp_path, questionnaire=q, control="CaMN", adjust="bonferroni", n_boot=300, seed=2)
    s = json.loads((tmp_path / "stats.json").read_text())
    rated = df[~df["is_practice"] & ~df["is_attention_check"]]
    for crit in ("realism", "diversity"):
        wil = s[crit]["posthoc"]["wilcoxon_holm"]
        assert [(r["a"], r["b"]) for r in wil] == [("CaMN", "DiffSHEG"), ("CaMN", "FaceCapGes")]
        for r in wil:
            assert r["p_adjusted"] == pytest.approx(min(1.0, 2 * r["p"])) and r["adjustment"] == "Bonferroni"
        b = rank_blocks(rated, crit, block="participant", conditions=CONDS)
        ref = effect_sizes(b, n_boot=300, seed=2, control="CaMN")
        w = s[crit]["effect_sizes"]["kendall_w"]
        assert (w["estimate"], w["ci_low"], w["ci_high"]) == pytest.approx(tuple(ref.kendall_w.iloc[0][
            ["estimate", "ci_low", "ci_high"]]))
        assert w["estimate"] == pytest.approx(s[crit]["kendall_w"])
        got = pd.DataFrame(s[crit]["effect_sizes"]["pairs"])
        pd.testing.assert_frame_equal(got, ref.pairs, check_dtype=False)
        # r_rb of the effect-size table is the Wilcoxon table's
        np.testing.assert_allclose(got["rank_biserial"], [r["rank_biserial"] for r in wil], rtol=1e-12)
        agree = pd.DataFrame(s[crit]["agreement"]["per_stimulus"])
        ref_agree = stimulus_agreement(rated, conditions=CONDS, criteria=[crit], adjust="bonferroni")
        np.testing.assert_allclose(agree["kendall_w"], ref_agree["kendall_w"], rtol=1e-12)
        np.testing.assert_allclose(agree["p_adjusted"], ref_agree["p_adjusted"], rtol=1e-12)
    rel = s["_questionnaire"]["reliability"][0]
    assert (rel["ci_low"], rel["ci_high"]) == pytest.approx(feldt_interval(rel["alpha"], 12, 4))
    assert {r["item"] for r in s["_questionnaire"]["item_reliability"]} == {"q0", "q1", "q2", "q3"}
    assert s["_meta"]["adjustment"]["method"] == "bonferroni" and s["_meta"]["control"] == "CaMN"
    tables = {p.name for p in (tmp_path / "tables").iterdir()}
    assert {"effect_sizes.csv", "kendall_w.csv", "agreement.csv", "agreement_summary.csv",
            "questionnaire_item_reliability.csv"} <= tables
    md = (tmp_path / "report.md").read_text()
    assert "against the control CaMN" in md and "Bonferroni-adjusted over the 2 comparisons" in md
    assert "Wilcoxon p_adj (Bonferroni)" in md and "Agreement between participants" in md
    assert "BCa bootstrap intervals (300 resamples of participants, seed 2" in md
    assert "Feldt's 95% interval" in md and "α if dropped" in md
    # the W interval printed in the results text is stats.json's, through the same formatter
    w = s["realism"]["effect_sizes"]["kendall_w"]
    assert f"Kendall's W = {s['realism']['kendall_w']:.2f} (95% CI {w['ci_low']:.2f}–{w['ci_high']:.2f})" in md
    assert len(a.criteria["realism"].posthoc["nemenyi"]) == 3  # the CD diagram still covers all pairs


def test_default_is_holm_over_all_pairs_and_bh_is_scipys(tmp_path) -> None:
    df = simulate_results(10, 2, seed=6)
    a = analyze(df, tmp_path / "holm", n_boot=100)
    wil = a.criteria["realism"].posthoc["wilcoxon_holm"]
    assert len(wil) == 3 and (wil["adjustment"] == "Holm").all()
    assert "Holm-adjusted over the 3 comparisons" in (tmp_path / "holm" / "report.md").read_text()
    b = analyze(df, tmp_path / "bh", n_boot=100, adjust="bh", interval="percentile")
    wil = b.criteria["realism"].posthoc["wilcoxon_holm"]
    np.testing.assert_allclose(wil["p_adjusted"], stats.false_discovery_control(wil["p"], method="bh"))
    assert "percentile interval" in (tmp_path / "bh" / "report.md").read_text()


def test_cli_flags_and_one_line_errors(tmp_path, capsys) -> None:
    csv = tmp_path / "results.csv"
    simulate_results(8, 2, seed=1).to_csv(csv, index=False)
    assert main([str(csv), "--out", str(tmp_path / "o"), "--adjust", "bh", "--control", "FaceCapGes",
                 "--interval", "percentile", "--bootstrap", "100"]) == 0
    s = json.loads((tmp_path / "o" / "stats.json").read_text())
    assert s["_meta"]["adjustment"]["name"] == "Benjamini–Hochberg" and s["_meta"]["control"] == "FaceCapGes"
    assert s["_meta"]["effect_size_intervals"]["bootstrap"] == "percentile"
    capsys.readouterr()
    assert main([str(csv), "--out", str(tmp_path / "x"), "--control", "Ours"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--control" in err[0] and "no condition 'Ours'" in err[0] and "CaMN" in err[0]


def test_exact_hodges_lehmann_level_is_stated_in_table_3(tmp_path) -> None:
    # 4 participants x 2 trials: A - B mean-rank differences 2, -1, -1.5, 0.5 (no ties, no zeros), so the
    # interval is exact: the 1st and 10th of 10 Walsh averages, at 1 - 2/16 = 87.5 %, not 95 %
    orders = [("BCA", "BCA"), ("ABC", "CAB"), ("CAB", "BCA"), ("ACB", "CAB")]
    rows = [{"participant": f"P{p}", "trial_index": t, "stimulus": f"s{t}", "criterion": "realism",
             "condition": cond, "rank": place + 1}
            for p, trials in enumerate(orders) for t, order in enumerate(trials) for place, cond in enumerate(order)]
    a = analyze(pd.DataFrame(rows), tmp_path, n_boot=50)
    ab = a.criteria["realism"].effect_sizes.pairs.iloc[0]
    assert (ab["a"], ab["b"], ab["hl_interval"]) == ("A", "B", "exact")
    assert (ab["hodges_lehmann"], ab["hl_ci_low"], ab["hl_ci_high"], ab["hl_conf_level"]) == (0.0, -1.5, 2.0, 0.875)
    assert "| −1.50 to 2.00 (at 87.5%) |" in (tmp_path / "report.md").read_text()
