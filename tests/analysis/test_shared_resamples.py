"""One analysis draws each participant-resample matrix once (issue 20), and the shared draws are the very
resamples each statistic would draw for itself (the intervals do not change)."""
import numpy as np

import results_analysis.bootstrap as bootstrap
import results_analysis.descriptives as descriptives
from results_analysis.analysis import run_analysis
from results_analysis.bradley_terry import bradley_terry
from results_analysis.descriptives import condition_summary
from results_analysis.effect_sizes import effect_sizes
from results_analysis.ranks import rank_blocks
from results_analysis.simulate import simulate_results


class _CountingRng:
    def __init__(self) -> None:
        self.calls = 0
        self.real = np.random.default_rng

    def __call__(self, seed):
        self.calls += 1
        return self.real(seed)


def test_one_draw_per_resample_matrix_and_the_same_intervals(monkeypatch):
    df = simulate_results(30, 4, seed=5, n_practice=0, n_attention=0)
    counter = _CountingRng()
    assert descriptives.np is bootstrap.np  # one numpy: one patched generator factory sees both modules' draws
    monkeypatch.setattr(np.random, "default_rng", counter)
    a = run_analysis(df, n_boot=300, seed=7)
    monkeypatch.undo()
    assert len(a.criteria) == 3
    # one draw: the mean-rank, Bradley-Terry and effect-size intervals of every criterion share the resamples
    # (instead of 3 x 3 draws, or one multinomial and one index draw before)
    assert counter.calls == 1
    for crit, res in a.criteria.items():  # each statistic alone, drawing its own resamples
        trial = rank_blocks(df, crit, block="trial", conditions=a.conditions)
        alone = condition_summary(trial, n_boot=300, seed=7)
        assert np.array_equal(alone[["ci_low", "ci_high"]].to_numpy(), res.summary[["ci_low", "ci_high"]].to_numpy())
        bt = bradley_terry(trial, n_boot=150, seed=7)
        assert np.array_equal(bt[["ci_low", "ci_high"]].to_numpy(), res.bradley_terry[["ci_low", "ci_high"]].to_numpy())
        es = effect_sizes(res.blocks, n_boot=300, seed=7)
        assert es.pairs[["rb_ci_low", "rb_ci_high"]].equals(res.effect_sizes.pairs[["rb_ci_low", "rb_ci_high"]])


def test_mean_rank_interval_is_scipy_bootstrap_percentile_interval():
    """The mean-rank interval resamples participants exactly as scipy.stats.bootstrap does (the matrix the
    effect sizes use): for one block per participant it is scipy's percentile interval of the mean."""
    from scipy.stats import bootstrap as scipy_bootstrap

    df = simulate_results(40, 3, seed=2, n_practice=0, n_attention=0)
    blocks = rank_blocks(df, "realism", block="participant")
    got = condition_summary(blocks, n_boot=400, ci=0.9, seed=11)
    for c in range(blocks.k):
        ref = scipy_bootstrap((blocks.ranks[:, c],), np.mean, n_resamples=400, confidence_level=0.9,
                              method="percentile", rng=np.random.default_rng(11)).confidence_interval
        assert np.allclose([got["ci_low"][c], got["ci_high"][c]], [ref.low, ref.high], rtol=0, atol=1e-12)
