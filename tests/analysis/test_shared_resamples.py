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
    # one multinomial draw (mean-rank and Bradley-Terry intervals of every criterion) and one index draw
    # (effect sizes of every criterion), instead of 3 x 3
    assert counter.calls == 2
    for crit, res in a.criteria.items():  # each statistic alone, drawing its own resamples
        trial = rank_blocks(df, crit, block="trial", conditions=a.conditions)
        alone = condition_summary(trial, n_boot=300, seed=7)
        assert np.array_equal(alone[["ci_low", "ci_high"]].to_numpy(), res.summary[["ci_low", "ci_high"]].to_numpy())
        bt = bradley_terry(trial, n_boot=150, seed=7)
        assert np.array_equal(bt[["ci_low", "ci_high"]].to_numpy(), res.bradley_terry[["ci_low", "ci_high"]].to_numpy())
        es = effect_sizes(res.blocks, n_boot=300, seed=7)
        assert es.pairs[["rb_ci_low", "rb_ci_high"]].equals(res.effect_sizes.pairs[["rb_ci_low", "rb_ci_high"]])
