"""The BCa jackknife of the effect-size statistics from column totals (totals minus one participant's row)
equals the direct jackknife that recomputes each statistic with one participant's weight set to zero, and
Kendall's W left-one-out equals scipy's Friedman statistic on the data without that participant."""
from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from results_analysis.bootstrap import ClusterSums, _jackknife, cluster_bootstrap
from results_analysis.effect_sizes import (_hodges_lehmann_stat, _kendall_w_stat, _rank_biserial_stat,
                                           _row_weights)
from results_analysis.ranks import rank_blocks
from results_analysis.simulate import simulate_results


def _cases():
    for seed, n, block in ((1, 12, "participant"), (2, 37, "participant"), (3, 9, "trial"), (4, 23, "trial")):
        df = simulate_results(n, 3, seed=seed, strengths=[1.0, 1.2, 0.9])
        df = df[~df.is_practice & ~df.is_attention_check]
        yield seed, rank_blocks(df, "realism", block=block)


def _parts(blocks):
    n_clusters, cluster = _row_weights(blocks)
    k = blocks.k
    diffs = [blocks.values[:, i] - blocks.values[:, j] for i in range(k) for j in range(i + 1, k)]
    parts = [_kendall_w_stat(blocks, cluster, n_clusters)]
    parts += [_rank_biserial_stat(d, cluster, n_clusters) for d in diffs]
    parts += [_hodges_lehmann_stat(d, cluster, n_clusters) for d in diffs]
    return n_clusters, parts


@pytest.mark.parametrize("seed,blocks", list(_cases()))
def test_jackknife_from_totals_equals_direct_recomputation(seed, blocks) -> None:
    n_clusters, parts = _parts(blocks)
    stacked = ClusterSums.stack(parts)
    fast = _jackknife(stacked, n_clusters)
    slow = _jackknife(lambda w: stacked(w), n_clusters)   # a plain function: P weight rows evaluated
    assert fast.shape == slow.shape == (n_clusters, len(parts))
    np.testing.assert_allclose(fast, slow, rtol=0, atol=1e-12)
    assert np.ptp(fast, axis=0).max() > 0  # the leave-one-out values do differ between participants


@pytest.mark.parametrize("seed,blocks", [c for c in _cases() if c[1].block == "participant"])
def test_kendall_w_left_one_out_equals_scipy_friedman(seed, blocks) -> None:
    n_clusters, cluster = _row_weights(blocks)
    jack = _kendall_w_stat(blocks, cluster, n_clusters).jackknife()[:, 0]
    for i in range(n_clusters):
        v = blocks.values[cluster != i]
        chi2 = stats.friedmanchisquare(*v.T).statistic
        assert jack[i] == pytest.approx(chi2 / (len(v) * (blocks.k - 1)), abs=1e-12)


@pytest.mark.parametrize("seed,blocks", list(_cases()))
def test_bca_intervals_unchanged_by_the_fast_jackknife(seed, blocks) -> None:
    n_clusters, parts = _parts(blocks)
    stacked = ClusterSums.stack(parts)
    a = cluster_bootstrap(stacked, n_clusters, n_boot=499, seed=seed)
    b = cluster_bootstrap(lambda w: stacked(w), n_clusters, n_boot=499, seed=seed)
    for x, y in ((a.estimate, b.estimate), (a.low, b.low), (a.high, b.high)):
        np.testing.assert_allclose(x, y, rtol=0, atol=1e-12)
    assert a.method == b.method
