"""``results-analysis``: analyse exported study results (CSV export or the SQLite results database).

Example: ``results-analysis results.csv --out analysis/ --group speaker --exclude-failed-attention``
writes analysis/stats.json, analysis/tables/*.csv, analysis/figures/*.png|svg, analysis/report.md and a
self-contained analysis/report.html.
"""
from __future__ import annotations

import argparse
import sys
import warnings
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from results_analysis.errors import AnalysisInputError


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="results-analysis", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("results", type=Path, help="tidy results CSV (studyapp export) or results .sqlite database")
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--block", choices=("participant", "trial"), default="participant",
                   help="blocks of the headline Friedman test: participants (default; each participant's mean "
                   "within-trial rank per condition, valid under repeated measures) or trials (every trial an "
                   "independent block, as many published studies report; then the secondary analysis)")
    p.add_argument("--group", action="append", default=[], metavar="COL",
                   help="also break the analysis down by this stimulus tag or participant group (repeatable)")
    p.add_argument("--questionnaire", type=Path, help="questionnaire CSV (participant,item,scale,value); "
                   "when omitted, the questionnaire the results carry is used (a database's questionnaire "
                   "table, the questionnaire columns of a `studyapp export` CSV)")
    p.add_argument("--exclude-failed-attention", action="store_true",
                   help="exclude participants who failed any attention check")
    p.add_argument("--exclude", default="", metavar="P1,P2", help="comma-separated participants to exclude")
    p.add_argument("--incomplete", choices=("error", "drop", "skillings-mack"), default="error",
                   help="a trial that does not rank every condition: stop (default), drop it (listwise deletion), "
                   "or add the Skillings-Mack test over all trials (other statistics on complete trials)")
    p.add_argument("--permutations", type=int, default=2000, metavar="N",
                   help="with --incomplete skillings-mack: within-trial shuffles for its permutation p-value "
                   "(default 2000; 0 = chi-squared approximation only)")
    p.add_argument("--alpha", type=float, default=0.05, help="significance level (default 0.05)")
    p.add_argument("--conover", action="store_true", help="add Conover's Friedman post-hoc tests")
    p.add_argument("--adjust", choices=("holm", "bh", "bonferroni"), default="holm",
                   help="adjustment of the post-hoc and per-stimulus p-values: holm (default; family-wise error), "
                   "bh (Benjamini-Hochberg; false discovery rate) or bonferroni")
    p.add_argument("--control", default=None, metavar="CONDITION",
                   help="compare every other condition with this one only (k-1 post-hoc comparisons, adjusted "
                   "over k-1), e.g. your model against each baseline")
    p.add_argument("--interval", choices=("bca", "percentile"), default="bca",
                   help="bootstrap interval of the effect sizes (W, r_rb; Hodges-Lehmann with --block trial): "
                   "bca (default) or percentile")
    p.add_argument("--bootstrap", type=int, default=2000, metavar="N", help="bootstrap resamples (default 2000)")
    p.add_argument("--paradigm-bootstrap", type=int, default=10_000, metavar="N",
                   help="participant resamples of the pairwise, mismatch and rating blocks' intervals (default "
                   "10000, as GENEA)")
    p.add_argument("--reference", default=None, metavar="CONDITION",
                   help="the rating blocks' hidden reference condition: shown in their tables, left out of their "
                   "tests")
    p.add_argument("--screen-reference", action="store_true",
                   help="with --reference: exclude from a rating block every participant who rated the hidden "
                   "reference below 90 in more than 15%% of the items (MUSHRA's post-screening), and say who")
    p.add_argument("--seed", type=int, default=0, help="bootstrap seed (default 0)")
    p.add_argument("--metrics", type=Path, metavar="FILE", help="objective metrics CSV (`studyapp metrics DESIGN "
                   "--out FILE`): reported per condition with each metric's rank correlation with the mean ranks")
    p.add_argument("--title", default=None, help="report title (default: the study's title, which a results "
                   "database and a `studyapp export` CSV carry, else 'Results: FILE')")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    from results_analysis import MISSING

    if MISSING is not None:  # an install without the "analysis" extra (a participant's): one line, no traceback
        print(f'error: results-analysis needs {MISSING.partition(".")[0]}, which is not installed: '
              'pip install "studyapp[analysis]"', file=sys.stderr)
        return 2
    from results_analysis.loader import load_questionnaire, load_results, normalize_questionnaire
    from results_analysis.report import analyze
    from results_analysis.study_meta import questionnaire_from_results, study_title

    try:
        if not 0 < args.alpha < 1:
            raise AnalysisInputError(None, "--alpha", f"{args.alpha} is not between 0 and 1")
        df = load_results(args.results)
        # --title wins; then the study's title the results carry; the file name only as the last resort.
        title = args.title or study_title(df) or f"Results: {args.results.name}"
        q = None
        if args.questionnaire is not None:
            q = load_questionnaire(args.questionnaire)
        elif _is_sqlite(args.results):
            q = load_questionnaire(args.results)
            q = q if len(q) else None
        else:  # a `studyapp export` CSV carries each participant's answers in its questionnaire columns
            q = questionnaire_from_results(df)
            q = normalize_questionnaire(q, args.results) if q is not None else None
            q = q if q is not None and len(q) else None
        metrics = None
        if args.metrics is not None:
            from results_analysis.objective_metrics import load_metrics

            metrics = load_metrics(args.metrics)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            a = analyze(df, args.out, title=title, block=args.block,
                        groups=args.group, questionnaire=q, exclude_failed_attention=args.exclude_failed_attention,
                        exclude=[x for x in args.exclude.split(",") if x.strip()], alpha=args.alpha,
                        conover=args.conover, n_boot=args.bootstrap, seed=args.seed, incomplete=args.incomplete,
                        sm_permutations=args.permutations, adjust=args.adjust, control=args.control,
                        interval=args.interval, metrics=metrics, paradigm_n_boot=args.paradigm_bootstrap,
                        reference=args.reference, screen_reference=args.screen_reference)
    except AnalysisInputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    for w in {str(w.message) for w in caught}:
        print(f"warning: {w}", file=sys.stderr)
    for crit, c in a.criteria.items():
        fr = c.friedman
        w = c.effect_sizes.kendall_w.iloc[0] if c.effect_sizes is not None else None
        w_ci = f" ({a.ci:.0%} CI {w['ci_low']:.2f}-{w['ci_high']:.2f})" if w is not None else ""
        print(f"{a.criterion_name(crit)}: chi2({fr.df}) = {fr.chi2:.2f}, p = {fr.p:.3g}, W = {fr.kendall_w:.2f}{w_ci}, "
              f"n = {fr.n_blocks} {a.block}s")
    for b in a.paradigm_blocks.values():
        print(block_summary(b, a.criterion_labels))
    if len(a.exclusions):
        print("excluded: " + "; ".join(f"{r.participant} ({r.reason})" for r in a.exclusions.itertuples()))
    print(f"report: {args.out / 'report.html'}")
    return 0


def block_summary(b, names: Mapping[str, str] | None = None) -> str:
    """One line per pairwise, mismatch or rating block: its headline numbers per criterion, each named by its
    label in ``names`` (criterion id -> label; default: the id), as the report names it."""
    parts = []
    for crit, r in b.results.items():
        crit = (names or {}).get(crit, crit)
        if b.paradigm == "pairwise":
            parts.append(f"{crit}: Elo " + ", ".join(
                f"{row.condition} " + (f"{row.elo:+.0f}" if np.isfinite(row.elo) else "not estimable")
                for row in r.elo.itertuples()))
        elif b.paradigm == "mismatch":
            parts.append(f"{crit}: matched preferred " + ", ".join(f"{row.condition} {row.rate:.0%}"
                                                                    for row in r.rates.itertuples()))
        else:
            fr = r.friedman.iloc[0]
            parts.append(f"{crit}: mean rating " + ", ".join(f"{row.condition} {row.mean:.1f}"
                                                            for row in r.summary.itertuples())
                         + f"; chi2({int(fr['df'])}) = {fr['chi2']:.2f}, p = {fr['p']:.3g}")
    screened = f"; screened out: {', '.join(b.excluded['participant'])}" if len(b.excluded) else ""
    return f"block {b.block} ({b.paradigm}, {b.n_participants} participants): " + "; ".join(parts) + screened


def _is_sqlite(path: Path) -> bool:
    try:
        with open(path, "rb") as fh:
            return fh.read(16).startswith(b"SQLite format 3")
    except OSError:
        return False


if __name__ == "__main__":
    sys.exit(main())
