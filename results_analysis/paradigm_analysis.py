"""The analysis of every pairwise, mismatch and rating block of a results frame, as data (no files).

Each block is analysed on its own rows, per criterion, in the study's order of blocks
(:func:`results_analysis.paradigms.blocks`), with its own conditions in the design's order:

* ``pairwise``: Bradley-Terry Elo with participant-bootstrap intervals, the win/tie/loss matrix and the
  pairwise Elo differences with intervals and adjusted bootstrap p-values (:mod:`results_analysis.pairwise`);
* ``mismatch``: matched-preference rate per condition against 0.5 and the Holm-adjusted comparisons between
  conditions (:mod:`results_analysis.mismatch`);
* ``rating``: means with participant-bootstrap intervals, Friedman and Wilcoxon-Holm on the participants' mean
  ratings (:mod:`results_analysis.rating`); with ``screen=True`` and a ``reference`` condition, MUSHRA's
  post-screening excludes from that block the participants who rated the hidden reference low.

Participants excluded from the study (by name, or for failed attention checks) are left out before this runs;
a participant screened out of a rating block stays in the other blocks (the rule is about the sliders).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import pandas as pd

from results_analysis.errors import AnalysisInputError
from results_analysis.mismatch import compare_conditions, matched_preference, trial_scores
from results_analysis.pairwise import bradley_terry_elo, elo_differences, reason_counts, win_matrix
from results_analysis.paradigms import analysed_rows, blocks, preference_trials
from results_analysis.rating import (SCREEN_MAX_SHARE, SCREEN_THRESHOLD, rating_summary, rating_tests,
                                     screen_reference)
from results_analysis.study_meta import condition_order


@dataclass
class PairwiseResult:
    """One criterion of a pairwise block: Elo per condition, the win/tie/loss matrix and the Elo differences."""

    criterion: str
    elo: pd.DataFrame
    wins: pd.DataFrame
    differences: pd.DataFrame
    #: reasons given with the preferences (see :func:`results_analysis.pairwise.reason_counts`)
    reasons: pd.DataFrame = field(default_factory=pd.DataFrame)


@dataclass
class MismatchResult:
    """One criterion of a mismatch block: rates against chance and the comparisons between conditions."""

    criterion: str
    rates: pd.DataFrame
    comparisons: pd.DataFrame


@dataclass
class RatingResult:
    """One criterion of a rating block: means, the Friedman test and the Wilcoxon post-hoc tests."""

    criterion: str
    summary: pd.DataFrame
    friedman: pd.DataFrame
    posthoc: pd.DataFrame


@dataclass
class BlockAnalysis:
    """The analysis of one block (see the module docstring)."""

    block: str
    paradigm: str
    conditions: list[str]
    results: dict[str, PairwiseResult | MismatchResult | RatingResult]
    n_participants: int
    n_trials: int
    n_boot: int
    ci: float
    seed: int
    adjust: str = "holm"
    reference: str | None = None
    #: rating blocks with screening: one row per participant who rated the reference (see screen_reference)
    screening: pd.DataFrame | None = None
    #: participants left out of this block, and why (the screening's exclusions)
    excluded: pd.DataFrame = field(default_factory=lambda: pd.DataFrame(columns=["participant", "reason"]))


def analyze_block(df: pd.DataFrame, block: str, paradigm: str, *, n_boot: int = 10_000, ci: float = 0.95,
                  seed: int = 0, adjust: str = "holm", reference: str | None = None, screen: bool = False,
                  threshold: float = SCREEN_THRESHOLD, max_share: float = SCREEN_MAX_SHARE) -> BlockAnalysis:
    """Analyse one block of a (validated, exclusion-applied) tidy frame, every criterion it asked.

    >>> from results_analysis.simulate import simulate_paradigm
    >>> b = analyze_block(simulate_paradigm("mismatch", 12, 3, seed=1), "mismatch", "mismatch", n_boot=200)
    >>> b.paradigm, list(b.results), b.n_participants, b.n_trials
    ('mismatch', ['realism'], 12, 36)
    """
    rows = analysed_rows(df, block)
    if rows.empty:
        raise AnalysisInputError(df.attrs.get("source"), f"block {block}", "no analysed answers in this block")
    screening = None
    excluded = pd.DataFrame(columns=["participant", "reason"])
    if paradigm == "rating" and screen:
        if reference is None or reference not in set(rows["condition"].astype(str)):
            raise AnalysisInputError(df.attrs.get("source"), f"block {block}",
                                     "screening needs the hidden reference condition the block showed "
                                     f"(--reference); {reference!r} is not one of its conditions")
        screening = screen_reference(rows, reference, threshold=threshold, max_share=max_share)
        out = screening[screening["excluded"]]
        excluded = out[["participant", "reason"]].reset_index(drop=True)
        rows = rows[~rows["participant"].astype(str).isin(set(out["participant"]))]
        if rows.empty:
            raise AnalysisInputError(df.attrs.get("source"), f"block {block}",
                                     f"every participant was screened out: each rated the hidden reference "
                                     f"{reference!r} below {threshold:g} in more than {max_share:.0%} of the items "
                                     "-- fix: check that --reference names the condition the block showed as its "
                                     "reference, or leave out --screen-reference")
    conditions = condition_order(rows)
    if paradigm == "rating" and reference in conditions:  # the reference last: it is not one of the systems
        conditions = [c for c in conditions if c != reference] + [reference]
    results: dict = {}
    for crit in dict.fromkeys(rows["criterion"].astype(str)):
        sub = rows[rows["criterion"].astype(str) == crit]
        sub.attrs.update(df.attrs)
        if paradigm == "pairwise":
            trials = preference_trials(sub)
            results[crit] = PairwiseResult(
                crit, bradley_terry_elo(trials, conditions=conditions, n_boot=n_boot, ci=ci, seed=seed),
                win_matrix(trials, conditions=conditions),
                elo_differences(trials, conditions=conditions, n_boot=n_boot, ci=ci, seed=seed, adjust=adjust),
                reason_counts(trials, conditions=conditions))
        elif paradigm == "mismatch":
            scores = trial_scores(sub)
            results[crit] = MismatchResult(
                crit, matched_preference(scores, conditions=conditions, n_boot=n_boot, ci=ci, seed=seed),
                compare_conditions(scores, conditions=conditions, n_boot=n_boot, ci=ci, seed=seed, adjust=adjust))
        elif paradigm == "rating":
            fr, post = rating_tests(sub, conditions=conditions, reference=reference, adjust=adjust)
            results[crit] = RatingResult(crit, rating_summary(sub, conditions=conditions, n_boot=n_boot, ci=ci,
                                                              seed=seed), fr, post)
        else:
            raise ValueError(f"block {block}: {paradigm!r} is not analysed here")
    return BlockAnalysis(block=block, paradigm=paradigm, conditions=conditions, results=results,
                         n_participants=int(rows["participant"].nunique()),
                         n_trials=int(rows[["participant", "trial_index"]].drop_duplicates().shape[0]),
                         n_boot=n_boot, ci=ci, seed=seed, adjust=adjust, reference=reference,
                         screening=screening, excluded=excluded)


def analyze_blocks(df: pd.DataFrame, **kwargs) -> dict[str, BlockAnalysis]:
    """:func:`analyze_block` for every non-rank block of ``df``, in the study's order; keyword arguments as
    there (a ``reference`` applies to rating blocks only).

    >>> import pandas as pd
    >>> from results_analysis.simulate import simulate_paradigm
    >>> df = pd.concat([simulate_paradigm("rating", 8, 2, seed=1),
    ...                 simulate_paradigm("pairwise", 8, 3, trial_offset=2, seed=1)])
    >>> {b: a.paradigm for b, a in analyze_blocks(df, n_boot=100).items()}
    {'rating': 'rating', 'pairwise': 'pairwise'}
    """
    if kwargs.get("reference") is not None:
        kwargs["reference"] = resolve_condition(df, kwargs["reference"])
    return {b: analyze_block(df, b, p, **kwargs) for b, p in blocks(df)}


def resolve_condition(df: pd.DataFrame, name: str) -> str:
    """The condition id ``name`` stands for: itself when it is an id, else the id whose ``condition_label`` it
    is (an analyst thinks in labels); an error lists the conditions when it is neither.

    >>> resolve_condition(pd.DataFrame({"condition": ["a1"], "condition_label": ["Ours"]}), "Ours")
    'a1'
    """
    ids = [str(c) for c in dict.fromkeys(df["condition"])]
    if name in ids:
        return name
    if "condition_label" in df.columns:
        by_label = {str(lb): str(c) for c, lb in zip(df["condition"], df["condition_label"]) if isinstance(lb, str)}
        if name in by_label:
            return by_label[name]
    raise AnalysisInputError(df.attrs.get("source"), "--reference",
                             f"no condition {name!r}; the conditions are {', '.join(ids)}")


def stats_entry(b: BlockAnalysis) -> dict:
    """The block's part of stats.json (condition ids, numbers as computed).

    >>> from results_analysis.simulate import simulate_paradigm
    >>> e = stats_entry(analyze_block(simulate_paradigm("rating", 6, 2, seed=1), "rating", "rating", n_boot=50))
    >>> e["paradigm"], sorted(e["criteria"]["realism"])[:3]
    ('rating', ['friedman', 'reference', 'reference_tested'])
    """
    out: dict = {"block": b.block, "paradigm": b.paradigm, "conditions": b.conditions,
                 "n_participants": b.n_participants, "n_trials": b.n_trials,
                 "bootstrap": {"n_boot": b.n_boot, "ci": b.ci, "seed": b.seed, "resampled": "participants",
                               "interval": "percentile"},
                 "excluded": b.excluded.to_dict("records"), "criteria": {}}
    for crit, r in b.results.items():
        if isinstance(r, PairwiseResult):
            entry = {"elo": r.elo.to_dict("records"), "wins": r.wins.to_dict("records"),
                     "differences": r.differences.to_dict("records"), "adjustment": b.adjust,
                     "reasons": r.reasons.to_dict("records"),
                     "ties": r.elo.attrs.get("ties"), "anchor": r.elo.attrs.get("anchor")}
        elif isinstance(r, MismatchResult):
            entry = {"rates": r.rates.to_dict("records"), "comparisons": r.comparisons.to_dict("records"),
                     "barnard_ties": r.comparisons.attrs.get("ties"), "adjustment": b.adjust}
        else:
            fr = r.friedman.iloc[0].to_dict()
            fr["n_incomplete"] = r.friedman.attrs.get("n_incomplete", 0)
            fr["mean_rank"] = r.friedman.attrs.get("mean_rank")
            entry = {"summary": r.summary.to_dict("records"), "friedman": fr,
                     "wilcoxon_holm": r.posthoc.to_dict("records"), "reference": b.reference,
                     "reference_tested": False}
        out["criteria"][crit] = entry
    if b.screening is not None:
        out["screening"] = {"reference": b.reference, "threshold": b.screening.attrs.get("threshold"),
                            "max_share": b.screening.attrs.get("max_share"),
                            "participants": b.screening.to_dict("records")}
    return out


def n_boot_note(b: BlockAnalysis) -> str:
    """How the block's intervals were computed, in words.

    >>> from results_analysis.simulate import simulate_paradigm
    >>> n_boot_note(analyze_block(simulate_paradigm("rating", 6, 2, seed=1), "rating", "rating", n_boot=50))
    '95% percentile intervals from 50 bootstrap resamples of participants (seed 0)'
    """
    return (f"{b.ci:.0%} percentile intervals from {b.n_boot} bootstrap resamples of participants (seed {b.seed})"
            if b.n_boot > 0 else "no bootstrap intervals (0 resamples)")


__all__ = ["BlockAnalysis", "MismatchResult", "PairwiseResult", "RatingResult", "analyze_block", "analyze_blocks",
           "n_boot_note", "resolve_condition", "stats_entry"]
