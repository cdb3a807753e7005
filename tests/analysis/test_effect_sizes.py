"""Effect-size intervals: Hodges-Lehmann with its distribution-free interval, and cluster-bootstrap intervals
of Kendall's W, r_rb and Hodges-Lehmann, each checked against an independent computation.

References:
* Hollander & Wolfe (1999), Nonparametric Statistical Methods, 2nd ed., section 3.2: the Hamilton
  depression data (R's ``wilcox.test`` example), Hodges-Lehmann estimate 0.46.
* The exact interval is the set of shifts the exact signed-rank test does not reject (Hollander & Wolfe
  3.3), checked here with scipy.stats.wilcoxon's own exact p-values; the normal-approximation interval is
  R's inversion of the corrected z test, checked with R's formula transcribed in conftest.py.
* scipy.stats.bootstrap (BCa and percentile) on a statistic written from the definitions with scipy
  (friedmanchisquare, wilcoxon), resampling participant indices with the same seed.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from results_analysis.effect_sizes import effect_sizes, hodges_lehmann, signed_rank_cdf, walsh_averages
from results_analysis.ranks import rank_blocks
from results_analysis.simulate import simulate_results

X = np.array([1.83, 0.50, 1.62, 2.48, 1.68, 1.88, 1.55, 3.06, 1.30])
Y = np.array([0.878, 0.647, 0.598, 2.05, 1.06, 1.29, 1.06, 3.14, 1.29])


def test_hodges_lehmann_published_estimate() -> None:
    h = hodges_lehmann(X - Y)
    assert h.estimate == pytest.approx(0.46, abs=5e-4)  # Hollander & Wolfe: 0.46
    assert h.method == "exact" and h.conf_level == pytest.approx(1 - 20 / 512)


def test_signed_rank_cdf_matches_enumeration_of_all_sign_patterns() -> None:
    for n in (1, 5, 9, 12):
        signs = (np.arange(2 ** n)[:, None] >> np.arange(n)) & 1          # every subset of ranks 1..n
        tplus = signs @ np.arange(1, n + 1)
        ref = np.array([(tplus <= t).mean() for t in range(n * (n + 1) // 2 + 1)])
        np.testing.assert_allclose(signed_rank_cdf(n), ref, rtol=1e-13)


def _exact_p(d: np.ndarray) -> float:
    return float(stats.wilcoxon(d, method="exact").pvalue)


@pytest.mark.parametrize("seed", range(8))
def test_exact_interval_is_the_set_the_exact_test_does_not_reject(seed: int) -> None:
    rng = np.random.default_rng(seed)
    d = rng.normal(0.3, 1.0, rng.integers(6, 30))
    h = hodges_lehmann(d, ci=0.9 if seed % 2 else 0.95)
    assert h.method == "exact"
    assert h.estimate == pytest.approx(np.median([(a + b) / 2 for i, a in enumerate(d) for b in d[i:]]))
    level = 1 - h.conf_level
    gaps = np.diff(walsh_averages(d))
    eps = gaps[gaps > 0].min() / 10
    for end in (h.ci_low, h.ci_high):
        inside = end + eps if end == h.ci_low else end - eps
        outside = end - eps if end == h.ci_low else end + eps
        assert _exact_p(d - inside) > level + 1e-12
        assert _exact_p(d - outside) <= level + 1e-12


@pytest.mark.parametrize("seed", range(8))
def test_normal_interval_inverts_rs_corrected_z_test(seed: int, r_wilcox_normal_p) -> None:
    rng = np.random.default_rng(100 + seed)
    # mean ranks of a few trials: heavy ties and zero differences, as participant blocks give
    d = np.round(rng.normal(0.4, 0.8, rng.integers(8, 60)) * 3) / 3
    d[: 2] = 0.0
    h = hodges_lehmann(d)
    # R widens the level (alpha doubled) until the ends lie within the data, with very few blocks only
    level = 1 - h.conf_level
    assert h.method == "normal approximation" and level in [pytest.approx(0.05 * 2 ** e) for e in range(4)]
    assert (level == pytest.approx(0.05)) == (d.size > 20)
    nz = d[d != 0]
    walsh = walsh_averages(nz)
    assert h.estimate == pytest.approx(np.median(walsh))
    eps = np.diff(np.unique(walsh)).min() / 10
    assert r_wilcox_normal_p(nz - (h.ci_low + eps))[1] >= level
    assert r_wilcox_normal_p(nz - (h.ci_low - eps))[1] < level
    assert r_wilcox_normal_p(nz - (h.ci_high - eps))[1] >= level
    assert r_wilcox_normal_p(nz - (h.ci_high + eps))[1] < level
    assert np.isclose(walsh, h.ci_low).any() and np.isclose(walsh, h.ci_high).any()


# --- bootstrap intervals against scipy.stats.bootstrap ------------------------------------------------


def _reference_stats(blocks, idx: np.ndarray, pair: tuple[int, int]) -> tuple[float, float, float]:
    """W, r_rb and HL of the participants ``idx`` (with repeats), written from the definitions."""
    ids = np.unique(blocks.participants)
    rows = np.concatenate([np.flatnonzero(blocks.participants == ids[i]) for i in idx])
    r = blocks.ranks[rows]
    n, k = r.shape
    chi2 = stats.friedmanchisquare(*r.T).statistic if np.ptp(r, axis=1).any() else 0.0
    w = chi2 / (n * (k - 1))
    d = blocks.values[rows, pair[0]] - blocks.values[rows, pair[1]]
    d = np.round(d, 10)
    d = d[d != 0]
    if d.size == 0:
        return w, 0.0, 0.0
    tplus = stats.wilcoxon(d, alternative="greater", method="asymptotic").statistic
    total = d.size * (d.size + 1) / 2
    hl = float(np.median([(a + b) / 2 for i, a in enumerate(d) for b in d[i:]]))
    return w, (2 * tplus - total) / total, hl


@pytest.mark.filterwarnings("ignore::RuntimeWarning", "ignore::scipy.stats.DegenerateDataWarning")
@pytest.mark.parametrize("block,interval", [("participant", "bca"), ("participant", "percentile"),
                                            ("trial", "bca")])
def test_bootstrap_intervals_equal_scipy_bootstrap(block: str, interval: str) -> None:
    df = simulate_results(11, 3, seed=5, n_practice=0, n_attention=0, strengths=[1.0, 0.7, 0.5])
    b = rank_blocks(df, "realism", block=block, conditions=["FaceCapGes", "DiffSHEG", "CaMN"])
    es = effect_sizes(b, n_boot=199, ci=0.9, seed=7, interval=interval)
    n_part = np.unique(b.participants).size
    for col, name in ((0, "kendall_w"), (1, "rank_biserial"), (2, "hodges_lehmann")):
        if name == "hodges_lehmann" and block == "participant":
            continue  # the distribution-free interval, tested above
        for p, (i, j) in enumerate([(0, 1), (0, 2), (1, 2)] if col else [(0, 1)]):
            def ref_ci(method: str):
                return stats.bootstrap((np.arange(n_part),), lambda idx: _reference_stats(b, idx, (i, j))[col],
                                       vectorized=False, n_resamples=199, confidence_level=0.9, method=method,
                                       rng=np.random.default_rng(7)).confidence_interval
            ref = ref_ci(interval)
            label = "BCa" if interval == "bca" else "percentile"
            if np.isnan(ref.low):  # a degenerate jackknife (discrete statistic): BCa undefined, percentile used
                ref, label = ref_ci("percentile"), "percentile (BCa undefined)"
            if col == 0:
                row = es.kendall_w.iloc[0]
                got = (row["estimate"], row["ci_low"], row["ci_high"])
                method = row["interval"].replace(" bootstrap", "")
            else:
                row = es.pairs.iloc[p]
                pre = "rb" if col == 1 else "hl"
                got = (row[name], row[f"{pre}_ci_low"], row[f"{pre}_ci_high"])
                method = row[f"{pre}_interval"].replace(" bootstrap", "")
            est = _reference_stats(b, np.arange(n_part), (i, j))[col]
            np.testing.assert_allclose(got, (est, ref.low, ref.high), rtol=1e-9, atol=1e-12,
                                       err_msg=f"{name} {i}-{j}")
            assert method == label


def test_participant_blocks_get_the_distribution_free_hl_interval_and_control_pairs() -> None:
    df = simulate_results(14, 2, seed=2, n_practice=0, n_attention=0)
    conds = ["FaceCapGes", "DiffSHEG", "CaMN"]
    b = rank_blocks(df, "realism", block="participant", conditions=conds)
    es = effect_sizes(b, n_boot=50, seed=1, control="CaMN")
    assert [(r.a, r.b) for r in es.pairs.itertuples()] == [("CaMN", "FaceCapGes"), ("CaMN", "DiffSHEG")]
    for r in es.pairs.itertuples():
        d = b.values[:, conds.index(r.a)] - b.values[:, conds.index(r.b)]
        h = hodges_lehmann(d)
        assert (r.hodges_lehmann, r.hl_ci_low, r.hl_ci_high, r.hl_interval) == \
               (h.estimate, h.ci_low, h.ci_high, h.method)
