"""The pairwise, mismatch and rating statistics against independent implementations and known truths.

* Bradley-Terry from preferences equals choix's ILSR, Zermelo's MM iteration and a direct maximum-likelihood fit
  of the trial outcomes (scipy.optimize, coded here from the likelihood); Elo 200 is P = 0.7597.
* Barnard's p-value equals a brute-force enumeration of every table with the observed column totals (exact
  rational comparison of the statistics), maximised over the nuisance parameter on a fine grid, and scipy's
  ``barnard_exact`` wherever scipy does not drop a table tied with the observed one; ties enter the table as
  documented.
* The participant-bootstrap intervals cover simulated truths at about their nominal rate.
* Friedman on mean ratings reproduces R's friedman.test (RoundingTimes: chi2 = 11.143, p = 0.003805).
"""
from __future__ import annotations

from fractions import Fraction

import choix
import numpy as np
import pandas as pd
import pytest
from scipy import optimize, stats

from results_analysis.mismatch import (barnard_exact, barnard_table, compare_conditions, matched_preference,
                                      trial_scores)
from results_analysis.pairwise import (bradley_terry_elo, elo_differences, elo_win_probability,
                                       participant_win_matrices, win_matrix)
from results_analysis.rating import participant_means, rating_summary, rating_tests, screen_reference
from results_analysis.simulate import simulate_paradigm

# --- pairwise ---------------------------------------------------------------------------------------------


def _trials(outcomes: list[tuple[str, str, int, int]]) -> pd.DataFrame:
    """(a, b, pref_a, count) -> trial rows, participants P0.. in turn."""
    rows = []
    for a, b, pref, count in outcomes:
        rows += [{"a": a, "b": b, "pref_a": pref} for _ in range(count)]
    t = pd.DataFrame(rows)
    t["participant"] = [f"P{i % 7}" for i in range(len(t))]
    return t


def _direct_mle(t: pd.DataFrame, conds: list[str]) -> np.ndarray:
    """Bradley-Terry by maximising the trial likelihood directly: every decided trial one Bernoulli outcome,
    every tie two half-weighted outcomes (one each way), log-strength of the first condition fixed at 0."""
    idx = {c: i for i, c in enumerate(conds)}
    ia, ib = t["a"].map(idx).to_numpy(), t["b"].map(idx).to_numpy()
    y = np.sign(t["pref_a"].to_numpy())

    def nll(free: np.ndarray) -> float:
        th = np.concatenate([[0.0], free])
        d = th[ia] - th[ib]
        win, lose = -np.log1p(np.exp(-d)), -np.log1p(np.exp(d))
        return -float(np.sum(np.where(y > 0, win, np.where(y < 0, lose, 0.5 * win + 0.5 * lose))))

    th = np.concatenate([[0.0], optimize.minimize(nll, np.zeros(len(conds) - 1), method="BFGS",
                                                  options={"gtol": 1e-10}).x])
    p = np.exp(th)
    return p / p.sum()


def _zermelo(wins: np.ndarray, iters: int = 20000) -> np.ndarray:
    """Zermelo's (1929) fixed point / Hunter's MM: p_i <- W_i / sum_j n_ij / (p_i + p_j)."""
    p = np.full(len(wins), 1.0 / len(wins))
    n = wins + wins.T
    for _ in range(iters):
        p = wins.sum(axis=1) / (n / (p[:, None] + p[None, :])).sum(axis=1)
        p /= p.sum()
    return p


def test_bradley_terry_equals_choix_zermelo_and_a_direct_fit() -> None:
    t = _trials([("A", "B", 2, 14), ("A", "B", -1, 6), ("A", "B", 0, 5), ("B", "C", 1, 11), ("C", "B", 2, 4),
                 ("B", "C", 0, 3), ("A", "C", 2, 17), ("C", "A", 1, 3), ("C", "A", 0, 4), ("D", "A", 1, 5),
                 ("D", "A", -2, 9), ("D", "B", 0, 6), ("B", "D", 1, 3), ("D", "C", 2, 8), ("D", "C", -1, 2)])
    conds = ["A", "B", "C", "D"]
    bt = bradley_terry_elo(t, conditions=conds, n_boot=0)
    _, per = participant_win_matrices(t, conditions=conds)
    wins = per.sum(axis=0)
    theta = choix.ilsr_pairwise_dense(wins, tol=1e-14, max_iter=100_000)
    ilsr = np.exp(theta - theta.max())
    assert bt["strength"].to_numpy() == pytest.approx(ilsr / ilsr.sum(), abs=1e-6)
    assert bt["strength"].to_numpy() == pytest.approx(_zermelo(wins), abs=1e-6)
    direct = _direct_mle(t, conds)
    assert bt["strength"].to_numpy() == pytest.approx(direct, abs=1e-5)
    # Elo = 400 log10 strength, mean 0
    elo = 400 * np.log10(direct)
    assert bt["elo"].to_numpy() == pytest.approx(elo - elo.mean(), abs=0.01)
    assert bt["elo"].mean() == pytest.approx(0.0, abs=1e-9)


def test_elo_200_is_preferred_76_percent() -> None:
    assert float(elo_win_probability(200)) == pytest.approx(1 / (1 + 10 ** -0.5)) == pytest.approx(0.7597, abs=5e-5)
    # a fit of 7597 wins to 2403 losses puts the two conditions 200 Elo apart
    t = _trials([("A", "B", 1, 7597), ("A", "B", -2, 2403)])
    bt = bradley_terry_elo(t, n_boot=0).set_index("condition")
    assert bt.loc["A", "elo"] - bt.loc["B", "elo"] == pytest.approx(200.0, abs=0.05)
    assert bt.loc["A", "elo"] == pytest.approx(100.0, abs=0.03)  # anchored: mean 0


def test_ties_half_or_dropped_and_the_win_matrix() -> None:
    t = _trials([("A", "B", 1, 6), ("A", "B", -1, 2), ("B", "A", 0, 4)])
    w = win_matrix(t).set_index(["a", "b"])
    assert w.loc[("A", "B")].tolist()[:4] == [6, 4, 2, 12] and w.loc[("B", "A")].tolist()[:4] == [2, 4, 6, 12]
    assert w.loc[("A", "B"), "score"] == pytest.approx(8 / 12)
    half = bradley_terry_elo(t, n_boot=0).set_index("condition")["strength"]
    drop = bradley_terry_elo(t, n_boot=0, ties="drop").set_index("condition")["strength"]
    assert half["A"] == pytest.approx(8 / 12)  # two conditions: strength = share of points
    assert drop["A"] == pytest.approx(6 / 8)


def test_a_condition_that_never_won_is_not_estimable() -> None:
    t = _trials([("A", "B", 1, 5), ("B", "A", 1, 3), ("A", "C", 2, 4), ("B", "C", 1, 4)])
    bt = bradley_terry_elo(t, n_boot=200, seed=1).set_index("condition")
    assert not bt.loc["C", "estimable"] and bt.loc["C", "note"] == "never won"
    assert np.isnan(bt.loc["C", ["elo", "ci_low", "ci_high"]].astype(float)).all()
    assert bt.loc["A", "elo"] - bt.loc["B", "elo"] == pytest.approx(400 * np.log10(5 / 3), abs=1e-4)


def test_bootstrap_is_seeded_and_resamples_participants() -> None:
    df = simulate_paradigm("pairwise", 10, 6, seed=3)
    a = bradley_terry_elo(df, n_boot=300, seed=5)
    assert a.equals(bradley_terry_elo(df, n_boot=300, seed=5))
    assert not a.equals(bradley_terry_elo(df, n_boot=300, seed=6))
    # one participant: no interval (nothing to resample between)
    one = bradley_terry_elo(df[df["participant"] == "P01"], n_boot=300)
    assert one["ci_low"].isna().all()


def test_elo_intervals_cover_the_truth() -> None:
    truth = {"A": 120.0, "B": 0.0, "C": -120.0}
    hits, reps = np.zeros(3), 40
    for r in range(reps):
        df = simulate_paradigm("pairwise", 18, 6, truth=truth, tie_rate=0.2, participant_sd=0.0, seed=100 + r)
        bt = bradley_terry_elo(df, conditions=list(truth), n_boot=400, seed=r)
        hits += ((bt["ci_low"] <= list(truth.values())) & (list(truth.values()) <= bt["ci_high"])).to_numpy()
    # nominal 95 %; 40 replications: a correct interval lands in [0.85, 1] with probability ~0.99
    assert (hits / reps >= 0.85).all(), hits / reps


# --- mismatch ---------------------------------------------------------------------------------------------


def _t2(x1: int, x2: int, n1: int, n2: int) -> Fraction:
    """The pooled Wald statistic squared, exactly."""
    p1, p2, p = Fraction(x1, n1), Fraction(x2, n2), Fraction(x1 + x2, n1 + n2)
    return Fraction(0) if p1 == p2 else (p1 - p2) ** 2 / (p * (1 - p) * (Fraction(1, n1) + Fraction(1, n2)))


def _barnard_brute_force(table: list[list[int]], grid: int = 2001) -> tuple[float, bool]:
    """Barnard's unconditional test, two-sided, pooled Wald statistic, by enumerating every table with the
    observed column totals (columns = samples, as scipy), deciding "at least as extreme" in exact rational
    arithmetic, and maximising the tail probability over the nuisance parameter on a grid. Also says whether
    scipy's float comparison picks the same extreme tables (it can drop the mirror table, whose |T| is the
    observed one computed in another order)."""
    (a, b), (c, d) = table
    n1, n2 = a + c, b + d
    obs = _t2(a, b, n1, n2)
    cells = [(x1, x2) for x1 in range(n1 + 1) for x2 in range(n2 + 1)]
    exact = {k for k in cells if _t2(*k, n1, n2) >= obs}

    def wald(x1: int, x2: int) -> float:  # as scipy computes it
        p1, p2, p = x1 / n1, x2 / n2, (x1 + x2) / (n1 + n2)
        return 0.0 if p1 == p2 else (p1 - p2) / np.sqrt(p * (1 - p) * (1 / n1 + 1 / n2))

    as_scipy = {k for k in cells if abs(wald(*k)) >= abs(wald(a, b))}
    x1s, x2s = np.array(sorted(exact)).T
    pis = np.linspace(0.0, 1.0, grid)
    probs = stats.binom.pmf(x1s[None, :], n1, pis[:, None]) * stats.binom.pmf(x2s[None, :], n2, pis[:, None])
    return float(probs.sum(axis=1).max()), as_scipy == exact


TABLES = [[[7, 8], [12, 3]], [[14, 9], [6, 11]], [[20, 12], [4, 12]], [[3, 3], [9, 10]], [[7, 12], [8, 3]],
          [[0, 3], [5, 2]], [[9, 4], [3, 10]], [[16, 5], [7, 13]]]


def test_barnard_equals_brute_force_and_scipy_where_scipy_finds_the_same_tables() -> None:
    same = differ = 0
    for table in TABLES:
        brute, scipy_exact = _barnard_brute_force(table)
        # the grid's maximum is a lower bound of the supremum the refinement finds
        assert brute - 1e-9 <= barnard_exact(table) <= brute + 1e-5, table
        if scipy_exact:
            assert barnard_exact(table) == pytest.approx(stats.barnard_exact(table).pvalue, abs=1e-7), table
            same += 1
        else:  # scipy 1.17 drops a table whose |T| equals the observed one up to rounding: a smaller p
            assert stats.barnard_exact(table).pvalue < barnard_exact(table), table
            differ += 1
    assert same >= 2 and differ >= 2, (same, differ)
    # e.g. [[7, 8], [12, 3]]: scipy gives 0.0598
    assert barnard_exact([[7, 8], [12, 3]]) == pytest.approx(0.06751, abs=1e-5)


def _mismatch_rows(counts: dict[str, tuple[int, int, int]]) -> pd.DataFrame:
    """Tidy mismatch rows with (matched preferred, equal, mismatched preferred) counts per condition."""
    rows, t = [], 0
    for cond, (won, tied, lost) in counts.items():
        for i, pref in enumerate([2] * won + [0] * tied + [-1] * lost):
            matched_left = i % 2 == 0
            for slot in (0, 1):
                matched = (slot == 0) == matched_left
                rows.append({"participant": f"P{i % 9}", "trial_index": t, "stimulus": "s", "criterion": "fit",
                             "condition": cond, "slot": slot, "paradigm": "mismatch", "matched": int(matched),
                             "preference": pref if matched else -pref})
            t += 1
    return pd.DataFrame(rows)


def test_matched_preference_counts_ties_half_and_tests_against_chance() -> None:
    df = _mismatch_rows({"A": (30, 10, 8), "B": (12, 5, 15)})
    r = matched_preference(df, n_boot=500).set_index("condition")
    assert r.loc["A", ["matched", "equal", "mismatched", "n"]].tolist() == [30, 10, 8, 48]
    assert r.loc["A", "rate"] == pytest.approx((30 + 5) / 48)
    assert r.loc["A", "p"] == pytest.approx(stats.binomtest(30, 38).pvalue)
    assert r.loc["B", "p"] == pytest.approx(stats.binomtest(12, 27).pvalue)
    assert r.loc["A", "ci_low"] < r.loc["A", "rate"] < r.loc["A", "ci_high"]
    s = trial_scores(df)
    assert sorted(s["score"].unique()) == [0.0, 0.5, 1.0]


def test_comparisons_barnard_on_the_documented_table_with_holm() -> None:
    counts = {"A": (30, 9, 8), "B": (12, 5, 15), "C": (18, 3, 16)}
    c = compare_conditions(_mismatch_rows(counts), n_boot=400)
    tables = {("A", "B"): [[34, 14], [13, 18]], ("A", "C"): [[34, 19], [13, 18]], ("B", "C"): [[14, 19], [18, 18]]}
    # 9 ties split 4 / 5 (the odd one to "not"), 5 ties 2 / 3, 3 ties 1 / 2
    assert barnard_table(30, 9, 8) == (34, 13) and barnard_table(12, 5, 15) == (14, 18)
    raw = []
    for r in c.itertuples():
        assert r.table == tables[(r.a, r.b)]
        assert r.p_barnard == barnard_exact(r.table)  # checked against brute force above
        raw.append(r.p_barnard)
    order = np.argsort(raw)
    holm = np.maximum.accumulate(np.minimum(1, np.sort(raw) * np.array([3, 2, 1])))
    assert c["p_barnard_adjusted"].to_numpy()[order] == pytest.approx(holm)
    assert (c["p_bootstrap_adjusted"] >= c["p_bootstrap"]).all()
    # A vs B: every resampled difference is positive, and 400 resamples support p = 2/401 at best, never 0
    assert c.loc[0, "p_bootstrap"] == pytest.approx(2 / 401) and c.loc[0, "ci_low"] > 0
    # dropping ties: the decided trials only
    d = compare_conditions(_mismatch_rows(counts), n_boot=0, ties="drop")
    assert d.loc[0, "table"] == [[30, 12], [8, 15]]


def test_mismatch_intervals_cover_the_truth() -> None:
    truth = {"A": 0.7, "B": 0.5}
    hits, reps = np.zeros(2), 40
    for r in range(reps):
        df = simulate_paradigm("mismatch", 16, 6, conditions=list(truth), truth=truth, seed=300 + r)
        m = matched_preference(df, conditions=list(truth), n_boot=400, seed=r)
        hits += ((m["ci_low"] <= list(truth.values())) & (list(truth.values()) <= m["ci_high"])).to_numpy()
    assert (hits / reps >= 0.85).all(), hits / reps


def test_a_mismatch_trial_needs_one_matched_slot() -> None:
    from results_analysis.errors import AnalysisInputError

    df = _mismatch_rows({"A": (2, 0, 1)})
    df.loc[1, "matched"] = 1
    with pytest.raises(AnalysisInputError, match="matched = 1 and the other with 0"):
        trial_scores(df)
    df = _mismatch_rows({"A": (2, 0, 1)})
    df.loc[1, "preference"] = 1
    with pytest.raises(AnalysisInputError, match="must hold p and -p"):
        trial_scores(df)


# --- rating -----------------------------------------------------------------------------------------------

ROUNDING_TIMES = np.array([
    [5.40, 5.50, 5.55], [5.85, 5.70, 5.75], [5.20, 5.60, 5.50], [5.55, 5.50, 5.40], [5.90, 5.85, 5.70],
    [5.45, 5.55, 5.60], [5.40, 5.40, 5.35], [5.45, 5.50, 5.35], [5.25, 5.15, 5.00], [5.85, 5.80, 5.70],
    [5.25, 5.20, 5.10], [5.65, 5.55, 5.45], [5.60, 5.35, 5.45], [5.05, 5.00, 4.95], [5.50, 5.50, 5.40],
    [5.45, 5.55, 5.50], [5.55, 5.55, 5.35], [5.45, 5.50, 5.55], [5.50, 5.45, 5.25], [5.65, 5.60, 5.40],
    [5.70, 5.65, 5.55], [6.30, 6.30, 6.25]])


def _rating_rows(means: np.ndarray, spread: float = 3.0) -> pd.DataFrame:
    """Two trials per participant whose ratings average to ``means`` (participants x conditions), plus a
    reference rated 95 and 99."""
    rows = []
    for p, row in enumerate(means):
        for t, sign in ((0, 1.0), (1, -1.0)):
            for c, m in enumerate(row):
                rows.append({"participant": f"P{p:02d}", "trial_index": t, "criterion": "quality",
                             "condition": "ABC"[c], "rating": m + sign * spread})
            rows.append({"participant": f"P{p:02d}", "trial_index": t, "criterion": "quality", "condition": "ref",
                         "rating": 95.0 + 4 * t})
    return pd.DataFrame(rows)


def test_friedman_on_mean_ratings_reproduces_r() -> None:
    df = _rating_rows(ROUNDING_TIMES * 10)
    assert participant_means(df, conditions=list("ABC")).to_numpy() == pytest.approx(ROUNDING_TIMES * 10)
    fr, post = rating_tests(df, reference="ref")
    assert fr["k"].iloc[0] == 3  # the reference is not tested
    assert fr["chi2"].iloc[0] == pytest.approx(11.143, abs=5e-4)  # R: friedman.test(RoundingTimes)
    assert fr["p"].iloc[0] == pytest.approx(0.003805, abs=5e-7)
    # Wilcoxon on the paired means as R's wilcox.test(x, y, paired = TRUE) computes it (ties: normal approx.)
    x, y = ROUNDING_TIMES[:, 0] * 10, ROUNDING_TIMES[:, 2] * 10
    d = np.round(x - y, 10)
    d = d[d != 0]
    ref = stats.wilcoxon(d, method="asymptotic", correction=True)
    ab = post.set_index(["a", "b"]).loc[("A", "C")]
    assert ab["p"] == pytest.approx(ref.pvalue)
    with_ref, _ = rating_tests(df, reference="ref", include_reference=True)
    assert with_ref["k"].iloc[0] == 4


def test_rating_means_with_participant_bootstrap() -> None:
    df = _rating_rows(ROUNDING_TIMES * 10)
    s = rating_summary(df, conditions=list("ABC") + ["ref"], n_boot=500, seed=2).set_index("condition")
    assert s.loc["A", "mean"] == pytest.approx(ROUNDING_TIMES[:, 0].mean() * 10)
    assert s.loc["ref", "mean"] == pytest.approx(97.0)
    assert s.loc["A", "n"] == 44 and s.loc["A", "n_participants"] == 22
    # participant bootstrap of a mean over equal-sized participants = bootstrap of the participants' means
    # (the resamples are scipy.stats.bootstrap's index draws, shared with the rank analyses' intervals)
    idx = np.random.default_rng(2).integers(0, 22, (500, 22))
    boot = (ROUNDING_TIMES[:, 0] * 10)[idx].mean(axis=1)
    assert [s.loc["A", "ci_low"], s.loc["A", "ci_high"]] == pytest.approx(np.quantile(boot, [0.025, 0.975]))


def test_reference_screening_mushra_rule() -> None:
    df = simulate_paradigm("rating", 10, 8, reference="hidden", bad_raters=["P03", "P07"], seed=5)
    s = screen_reference(df, "hidden")
    assert s.loc[s["excluded"], "participant"].tolist() == ["P03", "P07"]
    # the rule is "more than 15 %": 1 of 8 items (12.5 %) below 90 is kept, 2 of 8 (25 %) is not
    one = pd.DataFrame({"participant": ["X"] * 8 + ["Y"] * 8, "trial_index": list(range(8)) * 2, "criterion": "c",
                        "condition": "hidden", "rating": [80] + [95] * 7 + [80, 85] + [95] * 6})
    r = screen_reference(one, "hidden").set_index("participant")
    assert not r.loc["X", "excluded"] and r.loc["Y", "excluded"]
    assert r.loc["Y", "reason"] == "rated the hidden reference below 90 in 2 of 8 items (25% > 15%)"


def test_elo_differences_from_the_same_resamples_checked_with_choix() -> None:
    df = simulate_paradigm("pairwise", 12, 6, truth={"A": 150, "B": 0, "C": -150}, seed=8)
    conds = ["A", "B", "C"]
    bt = bradley_terry_elo(df, conditions=conds, n_boot=60, seed=3).set_index("condition")
    d = elo_differences(df, conditions=conds, n_boot=60, seed=3).set_index(["a", "b"])
    assert d.loc[("A", "C"), "difference"] == pytest.approx(bt.loc["A", "elo"] - bt.loc["C", "elo"])
    assert d.loc[("A", "C"), "p_preferred"] == pytest.approx(
        1 / (1 + 10 ** (-(bt.loc["A", "elo"] - bt.loc["C", "elo"]) / 400)))
    # each resample refitted one at a time by choix (ILSR) on the same participant multiplicities
    ids, per = participant_win_matrices(df, conditions=conds)
    idx = np.random.default_rng(3).integers(0, len(ids), (60, len(ids)))  # scipy.stats.bootstrap's draws
    w = np.stack([np.bincount(r, minlength=len(ids)) for r in idx])
    diffs = []
    for row in w:
        wins = np.einsum("p,pij->ij", row.astype(float), per) + 1e-3 * (1 - np.eye(3))
        theta = choix.ilsr_pairwise_dense(wins, tol=1e-12, max_iter=100_000)
        diffs.append(400 / np.log(10) * (theta[0] - theta[2]))
    assert [d.loc[("A", "C"), "ci_low"], d.loc[("A", "C"), "ci_high"]] == pytest.approx(
        np.quantile(diffs, [0.025, 0.975]), abs=1e-3)
    diffs = np.array(diffs)
    assert d.loc[("A", "C"), "p"] == pytest.approx(min(1, 2 * (1 + min((diffs <= 0).sum(), (diffs >= 0).sum())) / 61))
    assert (d["p_adjusted"] >= d["p"]).all()


def test_reasons_are_counted_per_preferred_condition() -> None:
    from results_analysis.errors import AnalysisInputError
    from results_analysis.pairwise import reason_counts
    from results_analysis.paradigms import preference_trials

    rows = []
    for t, (left, right, pref, reasons) in enumerate([("A", "B", 2, '["Hands", "Timing"]'), ("B", "A", 1, '["Hands"]'),
                                                      ("A", "B", 0, "[]"), ("A", "B", -1, '["Timing"]')]):
        for slot, (c, p) in enumerate(((left, pref), (right, -pref))):
            rows.append({"participant": "P1", "trial_index": t, "stimulus": "s", "criterion": "c", "condition": c,
                         "slot": slot, "preference": p, "reasons": reasons, "_where": f"line {2 + 2 * t + slot}"})
    df = pd.DataFrame(rows)
    r = reason_counts(preference_trials(df), conditions=["A", "B"]).set_index("reason")
    assert r.loc["Hands"].tolist() == [2, 2 / 3, 1, 1] and r.loc["Timing"].tolist() == [2, 2 / 3, 1, 1]
    df.loc[6, "reasons"] = df.loc[7, "reasons"] = "Timing"
    with pytest.raises(AnalysisInputError, match=r"line 8, column 'reasons': 'Timing' is not a JSON list"):
        reason_counts(preference_trials(df))
