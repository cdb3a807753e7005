"""Ties, Bradley-Terry and the participant-level headline (issue 17).

* The same answers with ties written 1,1,3 (min), 1.5,1.5,3 (average) or 2,2,3 (max) give identical
  statistics and p-values in every test, over many random datasets.
* Rank shares split a tied answer over the places it spans (checked against enumerating the orderings a
  tie stands for), so they sum to 100 %.
* Bradley-Terry matches ``choix`` (an independent implementation, ILSR) to 1e-6, including a condition that
  never wins, one that never loses and a near-degenerate case; it warns instead of stopping silently.
* The default analysis is participant-level and says so; ``--block trial`` reproduces R's
  ``friedman.test`` on its published example.
"""
from __future__ import annotations

import json
import warnings
from itertools import permutations
from pathlib import Path

import choix
import numpy as np
import pandas as pd
import pytest
from scipy import stats

from results_analysis import analyze, bradley_terry, fit_bradley_terry, pairwise_wins, run_analysis
from results_analysis.bradley_terry import ConvergenceWarning, estimability
from results_analysis.cli import main
from results_analysis.ranks import RankBlocks, place_shares, within_block_ranks

from test_published import ROUNDING_TIMES  # noqa: E402  (R's published friedman.test example)


def _answers(rng: np.random.Generator, k: int, n_part: int, n_trials: int, criteria=("realism", "diversity")):
    """Latent scores per participant x trial x criterion x condition, with plenty of exact ties."""
    conds = [f"c{i}" for i in range(k)]
    rows = []
    for p in range(n_part):
        for t in range(n_trials):
            for crit in criteria:
                # k values from k - 1 levels: every answer has a tie; half the conditions sometimes lead
                latent = rng.integers(0, k - 1, size=k) + (np.arange(k) >= k // 2) * rng.integers(0, 2)
                rows += [{"participant": f"P{p:02d}", "trial_index": t, "stimulus": f"s{t}", "criterion": crit,
                          "condition": c, "score": float(v)} for c, v in zip(conds, latent)]
    return pd.DataFrame(rows)


def _coded(df: pd.DataFrame, method: str) -> pd.DataFrame:
    """The ranks of each trial's scores with ties written by ``method`` (scipy rankdata: min/average/max)."""
    out = df.copy()
    out["rank"] = df.groupby(["participant", "trial_index", "criterion"])["score"].transform(
        lambda s: stats.rankdata(s.to_numpy(), method=method))
    return out.drop(columns="score")


def _everything(a) -> dict:
    """Every number of an analysis that a tie coding could change, as plain frames and dicts."""
    out = {}
    for crit, c in a.criteria.items():
        out[crit] = {"friedman": c.friedman.as_dict(), "sensitivity": c.sensitivity and c.sensitivity.as_dict(),
                     "posthoc": {m: t.reset_index(drop=True) for m, t in c.posthoc.items()},
                     "summary": c.summary, "bt": c.bradley_terry,
                     "sm": c.skillings_mack, "cd": c.critical_difference}
    for g, t in a.groups.items():
        out[f"group {g}"] = t
    return out


def _assert_same(x, y, where: str = "") -> None:
    if isinstance(x, pd.DataFrame):
        pd.testing.assert_frame_equal(x, y, check_exact=False, rtol=1e-12, atol=1e-12, obj=where)
    elif isinstance(x, dict):
        assert x.keys() == y.keys(), where
        for key in x:
            _assert_same(x[key], y[key], f"{where}/{key}")
    elif isinstance(x, (float, np.floating)) or (isinstance(x, tuple) and x and isinstance(x[0], float)):
        assert np.asarray(x, dtype=float) == pytest.approx(np.asarray(y, dtype=float), rel=1e-12, abs=1e-12,
                                                           nan_ok=True), where
    else:
        assert x == y, where


@pytest.mark.parametrize("seed", range(30))
def test_tie_coding_changes_no_statistic(seed: int) -> None:
    rng = np.random.default_rng(seed)
    k = int(rng.integers(3, 6))
    answers = _answers(rng, k, n_part=int(rng.integers(3, 8)), n_trials=int(rng.integers(2, 6)))
    answers["group"] = np.where(answers["participant"] < "P02", "a", "b")
    block = ("participant", "trial")[seed % 2]
    incomplete = "skillings-mack" if seed % 4 < 2 else "error"
    if incomplete == "skillings-mack":  # some trials lose one condition: the Skillings-Mack test reads them
        drop = answers.groupby(["participant", "trial_index", "criterion"]).head(1).sample(frac=0.3, random_state=seed)
        answers = answers.drop(index=drop.index)
    results = {}
    for method in ("min", "average", "max"):
        df = _coded(answers, method)
        assert method == "average" or (df["rank"] % 1 == 0).all()
        results[method] = _everything(run_analysis(df, block=block, conover=True, n_boot=30, groups=["group"],
                                                   incomplete=incomplete, sm_permutations=40, seed=seed))
    ties = _coded(answers, "average")["rank"] % 1 != 0
    assert ties.any()  # the data really have ties
    _assert_same(results["min"], results["average"], "min vs average")
    _assert_same(results["max"], results["average"], "max vs average")


def _shares_by_enumeration(ranks: np.ndarray) -> np.ndarray:
    """Place shares from first principles: a tie stands for every strict order of its members, equally likely."""
    n, k = ranks.shape
    shares = np.zeros((k, k))
    for row in ranks:
        orders = [p for p in permutations(range(k))
                  if all(row[p[i]] <= row[p[i + 1]] for i in range(k - 1))]  # p[place] = condition
        for p in orders:
            for place, cond in enumerate(p):
                shares[cond, place] += 1.0 / len(orders)
    return shares / n


@pytest.mark.parametrize("seed", range(10))
def test_place_shares_split_ties_and_sum_to_one(seed: int) -> None:
    rng = np.random.default_rng(100 + seed)
    k = int(rng.integers(2, 6))
    ranks = within_block_ranks(rng.integers(0, 3, size=(int(rng.integers(1, 30)), k)))
    got = place_shares(ranks)
    assert got == pytest.approx(_shares_by_enumeration(ranks), abs=1e-12)
    assert got.sum(axis=1) == pytest.approx(np.ones(k)) and got.sum(axis=0) == pytest.approx(np.ones(k))


def test_a_tie_for_first_is_half_a_first_place() -> None:
    r = within_block_ranks(np.array([[1, 1, 3], [1, 2, 3], [1, 1, 1]], dtype=float))
    assert place_shares(r) == pytest.approx(np.array([[(0.5 + 1 + 1 / 3) / 3, (0.5 + 1 / 3) / 3, 1 / 9],
                                                      [(0.5 + 1 / 3) / 3, (0.5 + 1 + 1 / 3) / 3, 1 / 9],
                                                      [1 / 9, 1 / 9, (1 + 1 + 1 / 3) / 3]]))


# --- Bradley-Terry against choix --------------------------------------------------------------------


def _choix(wins: np.ndarray) -> np.ndarray:
    """choix's ILSR maximum-likelihood strengths of a dense wins matrix, normalised to sum to 1."""
    theta = choix.ilsr_pairwise_dense(np.asarray(wins, dtype=float), tol=1e-14, max_iter=100_000)
    p = np.exp(theta - theta.max())
    return p / p.sum()


@pytest.mark.parametrize("seed", range(8))
def test_bradley_terry_matches_choix(seed: int) -> None:
    rng = np.random.default_rng(seed)
    k = int(rng.integers(3, 6))
    ranks = within_block_ranks(rng.normal(size=(int(rng.integers(20, 200)), k)) - np.linspace(0, 1.5, k))
    ranks[:5] = within_block_ranks(rng.integers(0, 2, size=(5, k)))  # ties: half a win each
    wins = pairwise_wins(ranks)
    assert fit_bradley_terry(wins) == pytest.approx(_choix(wins), abs=1e-6)


def test_bradley_terry_hard_cases_match_choix() -> None:
    # c2 never wins: no finite maximum-likelihood strength. Flagged, and the others are the maximum-
    # likelihood strengths among themselves (the limit of the full fit), as choix finds on that sub-matrix.
    ranks = np.array([[1, 2, 3]] * 30 + [[2, 1, 3]] * 10 + [[1.5, 1.5, 3]] * 4, dtype=float)
    blocks = RankBlocks(ranks, ranks, ["a", "b", "c2"], np.repeat([f"P{i}" for i in range(11)], 4), "trial")
    bt = bradley_terry(blocks, n_boot=200, seed=1)
    assert bt["estimable"].tolist() == [True, True, False] and bt["note"].tolist() == ["", "", "never won"]
    assert np.isnan(bt.loc[2, ["strength", "ci_low", "ci_high"]].astype(float)).all()
    wins = pairwise_wins(ranks)
    assert bt["strength"].to_numpy()[:2] == pytest.approx(_choix(wins[:2, :2]), abs=1e-6)
    # the pseudo-count fit (what each bootstrap resample uses) is the maximum-likelihood fit of the augmented
    # wins, which choix reaches too; a condition with ~1e-4 strength is exactly where MM crawled
    prior = 1e-3
    augmented = wins + prior * (1 - np.eye(3))
    assert fit_bradley_terry(wins, prior=prior) == pytest.approx(_choix(augmented), abs=1e-6)
    assert fit_bradley_terry(wins, prior=prior)[2] == pytest.approx(_choix(augmented)[2], rel=1e-6)
    # near-degenerate but finite: c2 won once in 2000 comparisons
    near = wins.copy() * 25
    near[2, 0] = 1.0
    assert estimability(near)[0].all()
    assert fit_bradley_terry(near) == pytest.approx(_choix(near), abs=1e-6)
    assert fit_bradley_terry(near)[2] == pytest.approx(_choix(near)[2], rel=1e-6)
    # one condition never loses: its strength tends to 1 and every other to 0: nothing is estimable
    top = np.array([[0, 5, 5], [0, 0, 3], [0, 2, 0]], dtype=float)
    est, notes = estimability(top)
    assert not est.any() and notes[0] == "never lost"
    with pytest.raises(ValueError, match="not finite"):
        fit_bradley_terry(top)


def test_bradley_terry_warns_instead_of_stopping_silently() -> None:
    wins = np.array([[0, 8, 8], [2, 0, 5], [2, 5, 0]], dtype=float)
    with pytest.warns(ConvergenceWarning, match="did not converge in 1 Newton steps"):
        fit_bradley_terry(wins, max_iter=1)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        fit_bradley_terry(np.tile(wins, (50, 1, 1)) * np.random.default_rng(0).uniform(0.1, 10, (50, 1, 1)))


def _never_wins_study() -> pd.DataFrame:
    """6 participants x 4 trials: 'bad' is always ranked last, 'a' and 'b' trade places."""
    rows = []
    for p in range(6):
        for t in range(4):
            first = "a" if (p + t) % 3 else "b"
            order = {first: 1, ("b" if first == "a" else "a"): 2, "bad": 3}
            rows += [{"participant": f"P{p}", "trial_index": t, "stimulus": f"s{t}", "criterion": "realism",
                      "condition": c, "rank": float(r)} for c, r in order.items()]
    return pd.DataFrame(rows)


def test_report_flags_a_strength_it_cannot_estimate(tmp_path: Path) -> None:
    a = analyze(_never_wins_study(), tmp_path, title="Never wins", n_boot=100)
    bt = a.criteria["realism"].bradley_terry.set_index("condition")
    assert not bt.loc["bad", "estimable"] and bt.loc["bad", "note"] == "never won"
    md = (tmp_path / "report.md").read_text()
    assert "bad not estimable (never won)" in md  # the text
    table4 = next(p for p in md.split("\n\n") if p.startswith("| criterion | condition | strength |"))
    assert "| realism | bad | not estimable (never won) |" in table4  # the table
    assert "0.00 (95% CI 0.00–0.00)" not in md and "0.00–0.00" not in md
    s = json.loads((tmp_path / "stats.json").read_text())
    row = next(r for r in s["realism"]["bradley_terry"] if r["condition"] == "bad")
    assert row["strength"] is None and row["estimable"] is False
    csv = pd.read_csv(tmp_path / "tables" / "bradley_terry.csv")
    assert csv.loc[csv.condition == "bad", "note"].item() == "never won"
    # the figure marks it in red words instead of drawing a bar at 0
    import matplotlib.pyplot as plt
    from results_analysis import figures
    fig = figures.bt_figure({"realism": a.criteria["realism"].bradley_terry})
    texts = [t.get_text() for ax in fig.axes for t in ax.texts]
    assert "not estimable (never won)" in texts
    assert len([p for p in fig.axes[0].patches]) == 2  # bars for a and b only
    plt.close(fig)


# --- the headline under repeated measures -----------------------------------------------------------


def test_default_headline_is_participant_level_and_says_so(tmp_path: Path) -> None:
    df = _never_wins_study()
    a = analyze(df, tmp_path, title="Blocks", n_boot=50)
    c = a.criteria["realism"]
    assert a.block == "participant" and c.friedman.n_blocks == 6 and c.sensitivity.n_blocks == 24
    # by hand: each participant's mean within-trial rank per condition, then scipy's Friedman over participants
    means = df.groupby(["participant", "condition"])["rank"].mean().unstack()[["a", "b", "bad"]]
    ref = stats.friedmanchisquare(*means.to_numpy().T)
    assert c.friedman.chi2 == pytest.approx(ref.statistic) and c.friedman.p == pytest.approx(ref.pvalue)
    md = (tmp_path / "report.md").read_text()
    opening = next(p for p in md.split("\n\n") if p.startswith("**realism.**"))  # no label: the id
    assert "The primary, participant-level Friedman test (each of the 6 participants a block" in opening
    assert "The secondary, trial-level test (every trial a block)" in opening and "pseudo-replication" in opening
    assert "Table 1. Friedman tests per criterion (primary analysis, blocks: participants)." in md
    method = md.split("# Method", 1)[1].split("# Results", 1)[0]
    assert "pseudo-replication" in method and "half to each place of a two-way tie" in method


@pytest.mark.parametrize("method", ["min", "average"])
def test_block_trial_reproduces_r_friedman_test(tmp_path: Path, method: str) -> None:
    """R's ?friedman.test example (rounding first base, 22 players x 3 methods; chi-squared = 11.143,
    p-value = 0.003805) written as a study: each player one trial, 11 trials from each of 2 participants,
    ranks of the times with ties written either way."""
    names = ["round_out", "narrow_angle", "wide_angle"]
    rows = []
    for i, times in enumerate(ROUNDING_TIMES):
        for cond, r in zip(names, stats.rankdata(times, method=method)):
            rows.append({"participant": f"P{i % 2}", "trial_index": i // 2, "stimulus": f"player{i}",
                         "criterion": "time", "condition": cond, "rank": r})
    csv = tmp_path / "rounding.csv"
    pd.DataFrame(rows).to_csv(csv, index=False)
    assert main([str(csv), "--out", str(tmp_path / "out"), "--block", "trial", "--bootstrap", "20"]) == 0
    s = json.loads((tmp_path / "out" / "stats.json").read_text())["time"]
    assert s["block"] == "trial" and s["n_blocks"] == 22
    assert s["chi2"] == pytest.approx(11.143, abs=5e-4) and s["p"] == pytest.approx(0.003805, abs=5e-7)
    assert s["sensitivity"]["block"] == "participant" and s["sensitivity"]["n_blocks"] == 2
    assert "The trial-level Friedman test (each of the 22 trials from 2 participants a block" in \
        (tmp_path / "out" / "report.md").read_text()
