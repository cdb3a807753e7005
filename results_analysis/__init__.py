"""Statistics of side-by-side user studies: rankings, pairwise and speech-mismatch preferences, ratings (reads
only exported results; never imports studyapp).

Functions take DataFrames / arrays and return DataFrames, in the manner of pingouin and scipy.stats:

>>> import pandas as pd
>>> from results_analysis import friedman
>>> wide = pd.DataFrame({"A": [1, 1, 2, 1], "B": [2, 3, 1, 2], "C": [3, 2, 3, 3]})
>>> float(friedman(wide)["chi2"].iloc[0])
4.5
"""
try:  # the statistics need the "analysis" extra; without it, `results-analysis` says what to install
    import pandas as _pandas  # noqa: F401
    import scipy as _scipy  # noqa: F401
    import importlib.util as _util

    if _util.find_spec("matplotlib") is None:  # the figures' (imported when drawn, not here: it is slow)
        raise ModuleNotFoundError("No module named 'matplotlib'", name="matplotlib")
except ModuleNotFoundError as _exc:
    MISSING: str | None = _exc.name
else:
    MISSING = None
if MISSING is None:
    from results_analysis.adjust import adjust_pvalues
    from results_analysis.agreement import agreement_summary, stimulus_agreement
    from results_analysis.analysis import Analysis, analyze_criterion, group_breakdown, run_analysis
    from results_analysis.bootstrap import cluster_bootstrap
    from results_analysis.bradley_terry import (ConvergenceWarning, bradley_terry, estimability, fit_bradley_terry,
                                                pairwise_wins)
    from results_analysis.descriptives import condition_summary
    from results_analysis.effect_sizes import EffectSizes, HodgesLehmann, effect_sizes, hodges_lehmann
    from results_analysis.errors import AnalysisInputError
    from results_analysis.exclusions import apply_exclusions
    from results_analysis.friedman import FriedmanResult, friedman, friedman_ranks, kendall_w
    from results_analysis.loader import load_questionnaire, load_results, load_study_title, normalize_results
    from results_analysis.mismatch import barnard_exact, compare_conditions, matched_preference
    from results_analysis.pairwise import bradley_terry_elo, elo_differences, elo_win_probability, win_matrix
    from results_analysis.paradigm_analysis import analyze_blocks
    from results_analysis.rating import rating_summary, rating_tests, screen_reference
    from results_analysis.posthoc import (conover, critical_difference, holm, nemenyi, nemenyi_q_alpha, posthoc_table,
                                          wilcoxon_holm)
    from results_analysis.questionnaire import cronbach_alpha, item_summary, scale_reliability
    from results_analysis.reliability import feldt_interval, item_analysis, item_reliability, scale_reliability_ci
    from results_analysis.ranks import RankBlocks, as_blocks, place_shares, rank_blocks, within_block_ranks
    from results_analysis.report import analyze
    from results_analysis.simulate import simulate_paradigm, simulate_results
    from results_analysis.validate import MixedDesignWarning, validate_results

__all__ = [
    "EffectSizes", "HodgesLehmann", "adjust_pvalues", "agreement_summary", "cluster_bootstrap", "effect_sizes",
    "feldt_interval", "hodges_lehmann", "item_analysis", "item_reliability", "scale_reliability_ci",
    "stimulus_agreement",
    "Analysis", "AnalysisInputError", "ConvergenceWarning", "FriedmanResult", "MixedDesignWarning",
    "RankBlocks", "analyze", "as_blocks", "analyze_criterion", "apply_exclusions", "bradley_terry",
    "condition_summary", "conover", "critical_difference", "cronbach_alpha", "estimability",
    "fit_bradley_terry", "friedman", "friedman_ranks", "group_breakdown", "holm", "item_summary", "kendall_w",
    "load_questionnaire", "load_results", "load_study_title", "nemenyi", "nemenyi_q_alpha", "normalize_results",
    "pairwise_wins", "place_shares", "posthoc_table", "rank_blocks", "run_analysis", "scale_reliability",
    "simulate_results", "validate_results", "within_block_ranks", "wilcoxon_holm",
    # the other response paradigms (pairwise, mismatch, rating blocks)
    "analyze_blocks", "barnard_exact", "bradley_terry_elo", "compare_conditions", "elo_differences",
    "elo_win_probability",
    "matched_preference", "rating_summary", "rating_tests", "screen_reference", "simulate_paradigm", "win_matrix",
]
