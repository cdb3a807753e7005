"""The whole rank analysis of a results frame, as data (no files): what ``report`` writes out.

Per criterion: the Friedman test on the chosen blocks and the other block type as a secondary analysis,
Nemenyi and Wilcoxon post-hoc tests (Conover optional) with a chosen p-value adjustment (Holm by default;
all pairs, or the k-1 pairs against a control condition), the critical difference, effect sizes with
intervals (:mod:`results_analysis.effect_sizes`), per-condition descriptives over all answered trials,
Bradley-Terry strengths and the agreement between participants per stimulus
(:mod:`results_analysis.agreement`). Optionally the same per level of stimulus tags / participant groups,
and questionnaire summaries with reliability (:mod:`results_analysis.reliability`).

The primary analysis uses participants as blocks (each participant's mean within-trial rank per
condition): a participant's trials are repeated measures of one person, so counting them as independent
blocks (``block='trial'``, the analysis many published studies report) overstates the evidence
(pseudo-replication). The trial-level test stays as the secondary analysis, and as the primary one with
``block='trial'`` to replicate a published analysis. Every test runs on within-block ranks, so how ties
were written (1,1,3 or 1.5,1.5,3) cannot change a result.

Conditions are analysed in the design's order, and ``Analysis.labels`` holds the name each is shown by
(:mod:`results_analysis.study_meta`); the numbers are computed, and stored, under the condition ids. Criteria
likewise: computed under their ids, shown by ``Analysis.criterion_name`` (the design's label, else the id).
"""
from __future__ import annotations

import warnings
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from results_analysis.adjust import ADJUSTMENTS
from results_analysis.agreement import agreement_summary, split_agreement
from results_analysis.bootstrap import INTERVALS, resample_weights, shared_resamples
from results_analysis.bradley_terry import bradley_terry
from results_analysis.descriptives import condition_summary
from results_analysis.effect_sizes import EffectSizes, effect_sizes
from results_analysis.errors import AnalysisInputError
from results_analysis.codes import FrameCodes, frame_codes
from results_analysis.exclusions import apply_exclusions, attention_summary, excluded_rows
from results_analysis.friedman import FriedmanResult, friedman_ranks
from results_analysis.loader import CORE_COLUMNS, normalize_results
from results_analysis.paradigm_analysis import BlockAnalysis, analyze_blocks
from results_analysis.paradigms import other_rows, rank_rows
from results_analysis.posthoc import conover as conover_test
from results_analysis.posthoc import critical_difference, nemenyi, wilcoxon_holm
from results_analysis.questionnaire import item_summary
from results_analysis.reliability import item_reliability, scale_reliability_ci
from results_analysis.ranks import (CriterionTable, RankBlocks, criterion_table, participant_index,
                                    place_shares, rank_blocks, rank_blocks_by, rank_blocks_with_trials,
                                    shared_trial_tables, split_table, table_with_trials, text_levels)
from results_analysis.skillings_mack import SkillingsMackResult, skillings_mack
from results_analysis.sqlite_schema import QUESTIONNAIRE_PREFIX
from results_analysis.study_meta import condition_labels, condition_order, criterion_labels
from results_analysis.validate import complete_codes, design_hashes, distinct_rows, validated_codes


@dataclass
class CriterionAnalysis:
    """Everything computed for one criterion."""

    criterion: str
    blocks: RankBlocks
    friedman: FriedmanResult
    sensitivity: FriedmanResult | None
    sensitivity_block: str
    summary: pd.DataFrame
    posthoc: dict[str, pd.DataFrame]
    critical_difference: float
    bradley_terry: pd.DataFrame
    skillings_mack: SkillingsMackResult | None = None
    effect_sizes: EffectSizes | None = None


@dataclass
class Analysis:
    """The analysis of one results frame (see :func:`run_analysis`)."""

    criteria: dict[str, CriterionAnalysis]
    conditions: list[str]
    block: str
    alpha: float
    n_participants: int
    n_trials: int
    exclusions: pd.DataFrame
    attention: pd.DataFrame
    n_practice_rows: int
    dropped_incomplete: int
    incomplete: str
    incomplete_blocks: int = 0
    groups: dict[str, pd.DataFrame] = field(default_factory=dict)
    questionnaire_items: pd.DataFrame | None = None
    questionnaire_reliability: pd.DataFrame | None = None
    warnings: list[str] = field(default_factory=list)
    source: str | None = None
    design_hashes: list[str] = field(default_factory=list)
    n_boot: int = 2000
    seed: int = 0
    sm_permutations: int = 0
    ci: float = 0.95
    conover: bool = False
    adjust: str = "holm"
    control: str | None = None
    interval: str = "bca"
    agreement: pd.DataFrame | None = None
    agreement_summary: pd.DataFrame | None = None
    questionnaire_item_reliability: pd.DataFrame | None = None
    #: condition id -> the name tables, figures and text show (its design label, else the id); ``conditions``
    #: is in the design's order (see :mod:`results_analysis.study_meta`)
    labels: dict[str, str] = field(default_factory=dict)
    #: block id -> the analysis of each pairwise, mismatch and rating block, in the study's order
    #: (:mod:`results_analysis.paradigm_analysis`); ``criteria`` holds the rank blocks' analysis (empty when
    #: the study has none)
    paradigm_blocks: dict[str, BlockAnalysis] = field(default_factory=dict)
    #: criterion id -> the name text, tables and figures show: its design label (``criterion_label``), else the id
    criterion_labels: dict[str, str] = field(default_factory=dict)

    def criterion_name(self, criterion: str) -> str:
        """What the report calls ``criterion``: its label, else its id."""
        return self.criterion_labels.get(criterion, criterion)


#: Core columns the rank analysis never reads from the rows it keeps, unless it breaks the results down by
#: one (see run_analysis).
_UNREAD_COLUMNS = frozenset({"session", "slot", "plays", "response_time_s", "trial_duration_s", "sample", "app_version",
                             "study_title", "block", "paradigm", "rating", "preference", "matched",
                             "motion_stimulus", "reasons"})


def group_columns(df: pd.DataFrame) -> list[str]:
    """Columns that can be used for breakdowns: everything that is not a core export column or an answer
    to the questionnaire."""
    return [c for c in df.columns if c not in CORE_COLUMNS and not str(c).startswith(QUESTIONNAIRE_PREFIX)]


def analyze_criterion(df: pd.DataFrame, criterion: str, *, conditions: list[str], block: str = "participant",
                      alpha: float = 0.05, conover: bool = False, n_boot: int = 2000, ci: float = 0.95,
                      seed: int = 0, skillings_mack_test: bool = False, sm_permutations: int = 2000,
                      adjust: str = "holm", control: str | None = None, interval: str = "bca",
                      ) -> CriterionAnalysis:
    """Analyse one criterion of a validated, exclusion-applied tidy frame.

    >>> from results_analysis.simulate import simulate_results
    >>> df = simulate_results(12, 4, seed=3, n_practice=0, n_attention=0)
    >>> a = analyze_criterion(df, "realism", conditions=["FaceCapGes", "DiffSHEG", "CaMN"], n_boot=100)
    >>> a.friedman.n_blocks, a.sensitivity.n_blocks
    (12, 48)
    """
    return _analyze_criterion(df, criterion, None, conditions=conditions, block=block, alpha=alpha, conover=conover,
                              n_boot=n_boot, ci=ci, seed=seed, skillings_mack_test=skillings_mack_test,
                              sm_permutations=sm_permutations, adjust=adjust, control=control, interval=interval)


def _analyze_criterion(df: pd.DataFrame, criterion: str, table: CriterionTable | None, *, conditions: list[str],
                       block: str, alpha: float, conover: bool, n_boot: int, ci: float, seed: int,
                       skillings_mack_test: bool, sm_permutations: int, adjust: str, control: str | None,
                       interval: str) -> CriterionAnalysis:
    """:func:`analyze_criterion`, from the criterion's ``table`` when given (:func:`ranks.criterion_table`)."""
    sm = None
    if skillings_mack_test:
        sm = skillings_mack(rank_blocks(df, criterion, block="trial", conditions=conditions,
                                        complete_only=False).values, n_perm=sm_permutations, seed=seed)
    other = "participant" if block == "trial" else "trial"
    by_participant, by_trial = (
        rank_blocks_with_trials(df, criterion, block="participant", conditions=conditions) if table is None else
        table_with_trials(df, criterion, table, block="participant", conditions=conditions))
    blocks, other_blocks = (by_trial, by_participant) if block == "trial" else (by_participant, by_trial)
    if blocks.n < 2:
        raise AnalysisInputError(df.attrs.get("source"), f"criterion {criterion}",
                                 f"only {blocks.n} complete block(s) left after exclusions: nothing to test")
    sens = friedman_ranks(other_blocks.ranks) if other_blocks.n >= 2 else None
    trial_blocks = blocks if block == "trial" else other_blocks
    fr = friedman_ranks(blocks.ranks)
    # Wilcoxon pairs the blocks' within-trial ranks (a participant's mean of them): never the raw answers.
    post = {"nemenyi": nemenyi(blocks.ranks, conditions, alpha=alpha),
            "wilcoxon_holm": wilcoxon_holm(blocks.values, conditions, adjust=adjust, control=control)}
    if conover:
        post["conover"] = conover_test(blocks.ranks, conditions, adjust=adjust, control=control)
    return CriterionAnalysis(
        criterion=criterion, blocks=blocks, friedman=fr, sensitivity=sens, sensitivity_block=other,
        summary=condition_summary(trial_blocks, n_boot=n_boot, ci=ci, seed=seed),
        posthoc=post, critical_difference=critical_difference(blocks.k, blocks.n, alpha),
        bradley_terry=bradley_terry(trial_blocks, n_boot=n_boot // 2, ci=ci, seed=seed), skillings_mack=sm,
        effect_sizes=effect_sizes(blocks, n_boot=n_boot, ci=ci, seed=seed, interval=interval, control=control))


def group_breakdown(df: pd.DataFrame, column: str, *, conditions: list[str], criteria: Sequence[str],
                    block: str = "participant") -> pd.DataFrame:
    """The Friedman table per level of ``column`` (a stimulus tag or participant group) and criterion.

    Columns: group, level, criterion, n_blocks, n_participants, chi2, df, p, kendall_w, mean_rank_<condition>...
    and share_rank_1_<condition>....
    """
    return _group_breakdown(df, column, None, conditions=conditions, criteria=criteria, block=block)


def _group_breakdown(df: pd.DataFrame, column: str, tables: dict[str, CriterionTable] | None, *,
                     conditions: list[str], criteria: Sequence[str], block: str) -> pd.DataFrame:
    """:func:`group_breakdown`, splitting each criterion's ``tables`` entry when given."""
    if column not in df.columns:
        raise AnalysisInputError(df.attrs.get("source"), f"column '{column}'",
                                 f"no such column to group by; available: {', '.join(group_columns(df)) or 'none'}")
    rows = []
    levels = text_levels(df[column], "(none)")  # sorted levels
    # each criterion's trials x conditions matrix is built once and split by level (sorted, as groupby sorts)
    split = {crit: (rank_blocks_by(df, crit, levels, block=block, conditions=conditions) if tables is None else
                    split_table(df, crit, tables[crit], levels, block=block, conditions=conditions))
             for crit in criteria}
    for level in sorted(split[criteria[0]]) if criteria else []:
        for crit in criteria:
            b, tb = split[crit][level]
            row = {"group": column, "level": level, "criterion": crit, "n_blocks": b.n,
                   "n_participants": int(participant_index(b.participants)[0].size)}
            if b.n >= 2:
                fr = friedman_ranks(b.ranks)
                row.update(chi2=fr.chi2, df=fr.df, p=fr.p, kendall_w=fr.kendall_w)
                row.update({f"mean_rank_{c}": v for c, v in zip(conditions, fr.mean_rank)})
            else:
                row.update(chi2=np.nan, df=len(conditions) - 1, p=np.nan, kendall_w=np.nan)
                row.update({f"mean_rank_{c}": (float(b.ranks[0, i]) if b.n else np.nan)
                            for i, c in enumerate(conditions)})
            if b.n:
                first = place_shares(tb.ranks)[:, 0]  # a tie for first counts half (or a third ...)
                row.update({f"share_rank_1_{c}": float(first[i]) for i, c in enumerate(conditions)})
            rows.append(row)
    return pd.DataFrame(rows)


def run_analysis(df: pd.DataFrame, *, block: str = "participant", groups: Iterable[str] = (),
                 questionnaire: pd.DataFrame | None = None, exclude_failed_attention: bool = False,
                 exclude: Iterable[str] = (), alpha: float = 0.05, conover: bool = False, n_boot: int = 2000,
                 ci: float = 0.95, seed: int = 0, incomplete: str = "error", sm_permutations: int = 2000,
                 adjust: str = "holm", control: str | None = None, interval: str = "bca",
                 paradigm_n_boot: int = 10_000, reference: str | None = None,
                 screen_reference: bool = False) -> Analysis:
    """Validate, apply exclusions and analyse every criterion (see module docstring).

    The rank analysis uses the rows of paradigm ``rank`` only; every pairwise, mismatch and rating block is
    analysed by :func:`results_analysis.paradigm_analysis.analyze_blocks` (``paradigm_n_boot`` participant
    resamples, 10,000 by default as GENEA; ``reference``: the rating blocks' hidden reference condition, left
    out of their tests; ``screen_reference``: MUSHRA's post-screening of participants who rate it low) into
    ``Analysis.paradigm_blocks``, after the same exclusions.

    ``block='participant'`` (default) is the primary analysis over participants; ``block='trial'`` makes the
    trial-level Friedman test the headline, as published analyses that count trials as blocks do.

    ``incomplete='drop'`` deletes trials that do not rank every condition (listwise deletion) instead of
    stopping with an error; ``incomplete='skillings-mack'`` adds the Skillings-Mack test over all trials
    (incomplete ones included) per criterion, with a permutation p-value from ``sm_permutations``
    within-trial shuffles (0: chi-squared only), while the Friedman, post-hoc and descriptive statistics use
    the complete trials. Warnings (e.g. mixed design hashes) are collected in ``Analysis.warnings``
    and also re-emitted.

    ``adjust`` ('holm', 'bh' or 'bonferroni') adjusts the Wilcoxon (and Conover) p-values and the
    per-stimulus agreement tests; ``control`` names a condition to compare every other one with (k-1 pairs,
    adjusted over k-1) instead of all pairs; ``interval`` ('bca' or 'percentile') is the bootstrap interval
    of the effect sizes.
    """
    if adjust not in ADJUSTMENTS:
        raise AnalysisInputError(df.attrs.get("source"), "--adjust",
                                 f"{adjust!r} is not one of {', '.join(ADJUSTMENTS)}")
    if interval not in INTERVALS:
        raise AnalysisInputError(df.attrs.get("source"), "--interval",
                                 f"{interval!r} is not one of {', '.join(INTERVALS)}")
    df = normalize_results(df)  # frames from studyapp's export_dataframe come with their own dtypes
    names = criterion_labels(df)
    others, df = other_rows(df), rank_rows(df)
    block_options = dict(n_boot=paradigm_n_boot, ci=ci, seed=seed, adjust=adjust, reference=reference,
                         screen=screen_reference)
    if df.empty and len(others):
        return _paradigms_only(others, names, block=block, exclude_failed_attention=exclude_failed_attention,
                               exclude=exclude, alpha=alpha, n_boot=n_boot, ci=ci, seed=seed, incomplete=incomplete,
                               adjust=adjust, interval=interval, block_options=block_options)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        # participant, trial, criterion and condition codes, factorized once: the checks, exclusions and every
        # criterion's trials x conditions matrix (split by breakdown level, stimulus or not at all) use them
        checked, codes = validated_codes(df)
    notes = [str(w.message) for w in caught]
    for w in caught:
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    # the analysis reads the key, flags, labels, design hash and group columns of the rows it keeps: the
    # bookkeeping columns and questionnaire answers are left out of the copy of every kept row (a large study's
    # frame has a million rows)
    groups = list(groups)
    needed = checked[[c for c in checked.columns if c in groups or (
        c not in _UNREAD_COLUMNS and not str(c).startswith(QUESTIONNAIRE_PREFIX))]]
    needed.attrs.update(checked.attrs)
    kept, excluded, keep = excluded_rows(needed, codes, exclude_failed_attention=exclude_failed_attention,
                                         exclude=exclude)
    # Completeness is judged on what is analysed: an excluded participant's broken trial does not matter.
    kept, codes = complete_codes(kept, codes.take(keep) if codes is not None else None, incomplete=incomplete)
    if kept.empty:
        raise AnalysisInputError(df.attrs.get("source"), None, "no answers left after exclusions "
                                 "(practice and attention-check trials are never analysed)")
    # The design's order (ids in order where the table has no positions); the labels are for display only.
    conditions = condition_order(kept)
    if len(conditions) < 2:
        raise AnalysisInputError(df.attrs.get("source"), "column 'condition'", "fewer than 2 conditions")
    labels = condition_labels(kept, conditions)
    if len(others):  # the other blocks' conditions are shown by their labels too
        labels = condition_labels(others, condition_order(others)) | labels
    if control is not None and control not in conditions:
        # an analyst thinks in labels: accept one (labels are unique among labels and ids, see the design)
        by_label = {name: cid for cid, name in labels.items()}
        if control not in by_label:
            raise AnalysisInputError(df.attrs.get("source"), "--control",
                                     f"no condition {control!r}; the conditions are "
                                     + ", ".join(f"{c} ({labels[c]})" if labels.get(c, c) != c else c
                                                 for c in conditions))
        control = by_label[control]
    codes = codes if codes is not None else frame_codes(kept)
    criteria = [str(c) for c in codes.criteria[codes.present("criterion")]]  # in order of appearance
    tables = {c: criterion_table(codes, c, conditions) for c in criteria}
    sm = incomplete == "skillings-mack"
    # shared_resamples: the criteria and intervals resample the same participants with the same seed, so the
    # resample matrix is drawn once (mean-rank, Bradley-Terry and effect-size intervals alike); it is drawn in
    # the background (for every participant, as the criteria's blocks normally hold them all) while the
    # breakdowns, which need none, are computed
    with shared_resamples(), shared_trial_tables():
        n_part = codes.n_present("participant")
        if n_boot > 0 and n_part >= 2:
            resample_weights(n_part, n_boot, seed, background=True)
        by_group = {g: _group_breakdown(kept, g, tables, conditions=conditions, criteria=criteria, block=block)
                    for g in groups}
        agreement = split_agreement(kept, tables, conditions=conditions, criteria=criteria, adjust=adjust)
        # caught: e.g. a Bradley-Terry fit that did not converge
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            results = {c: _analyze_criterion(kept, c, tables[c], conditions=conditions, block=block, alpha=alpha,
                                             conover=conover, n_boot=n_boot, ci=ci, seed=seed,
                                             skillings_mack_test=sm, sm_permutations=sm_permutations,
                                             adjust=adjust, control=control, interval=interval) for c in criteria}
    for w in caught:
        notes.append(str(w.message))
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    items = reliability = item_rel = None
    if questionnaire is not None and len(questionnaire):
        q = questionnaire[~questionnaire["participant"].astype(str).isin(set(excluded["participant"]))]
        items, reliability, item_rel = item_summary(q), scale_reliability_ci(q, ci=ci), item_reliability(q)
    hashes = design_hashes(kept)
    paradigm_blocks = {}
    if len(others):
        gone = set(excluded["participant"].astype(str))
        rest = others[~others["participant"].astype(str).isin(gone)]
        rest.attrs.update(others.attrs)
        paradigm_blocks = analyze_blocks(rest, **block_options)
    return Analysis(paradigm_blocks=paradigm_blocks, criteria=results, conditions=conditions, block=block, alpha=alpha,
                    n_participants=n_part,
                    n_trials=_n_trials(kept, codes), exclusions=excluded,
                    attention=attention_summary(checked), n_practice_rows=int(kept.attrs.get("n_practice_rows", 0)),
                    dropped_incomplete=int(kept.attrs.get("dropped_incomplete", 0)), incomplete=incomplete,
                    incomplete_blocks=int(kept.attrs.get("incomplete_blocks", 0)),
                    groups=by_group, questionnaire_items=items, questionnaire_reliability=reliability,
                    warnings=notes, source=df.attrs.get("source"), design_hashes=[str(h) for h in hashes],
                    n_boot=n_boot, seed=seed, ci=ci, conover=conover,
                    sm_permutations=sm_permutations if incomplete == "skillings-mack" else 0,
                    adjust=adjust, control=control, interval=interval, agreement=agreement,
                    agreement_summary=agreement_summary(agreement, alpha=alpha),
                    questionnaire_item_reliability=item_rel, labels=labels, criterion_labels=names)


def _n_trials(kept: pd.DataFrame, codes: FrameCodes) -> int:
    """``distinct_rows(kept, ["participant", "trial_index"])``, from the frame's codes."""
    key, span = codes.trial_keys()
    if (codes.participant < 0).any() or (codes.trial < 0).any():  # a missing value: as distinct_rows counts it
        return distinct_rows(kept, ["participant", "trial_index"])
    if span <= 4 * len(key) + 4096:
        return int(np.count_nonzero(np.bincount(key, minlength=span)))
    return int(pd.unique(key).size)


def _paradigms_only(df: pd.DataFrame, names: dict[str, str], *, block: str, exclude_failed_attention: bool,
                    exclude: Iterable[str], alpha: float, n_boot: int, ci: float, seed: int, incomplete: str,
                    adjust: str, interval: str, block_options: dict) -> Analysis:
    """The analysis of a study without a rank block: exclusions, then every block of another paradigm."""
    kept, excluded = apply_exclusions(df, exclude_failed_attention=exclude_failed_attention, exclude=exclude)
    if kept.empty:
        raise AnalysisInputError(df.attrs.get("source"), None, "no answers left after exclusions "
                                 "(practice and attention-check trials are never analysed)")
    conditions = condition_order(kept)
    hashes = design_hashes(kept)
    notes: list[str] = []
    if len(hashes) > 1:
        notes.append(f"results mix {len(hashes)} study designs: {', '.join(map(str, hashes))}")
    return Analysis(criteria={}, conditions=conditions, block=block, alpha=alpha,
                    n_participants=int(kept["participant"].nunique()),
                    n_trials=distinct_rows(kept, ["participant", "trial_index"]),
                    exclusions=excluded, attention=attention_summary(df),
                    n_practice_rows=int(kept.attrs.get("n_practice_rows", 0)), dropped_incomplete=0,
                    incomplete=incomplete, warnings=notes, source=df.attrs.get("source"),
                    design_hashes=[str(h) for h in hashes], n_boot=n_boot, seed=seed, ci=ci, adjust=adjust,
                    interval=interval, labels=condition_labels(kept, conditions),
                    paradigm_blocks=analyze_blocks(kept, **block_options), criterion_labels=names)
