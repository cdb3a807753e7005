"""Write the analysis of a results frame to a folder: stats.json, tables/*.csv, figures/*.png|svg,
report.md and a self-contained report.html that reads like a results section: the rank analysis (when the
study has rank rows), then one section per pairwise, mismatch or rating block
(:mod:`results_analysis.paradigm_report`).

>>> import tempfile, pathlib
>>> from results_analysis.simulate import simulate_results
>>> out = pathlib.Path(tempfile.mkdtemp())
>>> a = analyze(simulate_results(8, 4, seed=2), out, title="Demo", n_boot=200)
>>> sorted(p.name for p in out.iterdir())
['figures', 'report.html', 'report.md', 'stats.json', 'tables']
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import scipy

from results_analysis import effects_report
from results_analysis.analysis import Analysis, CriterionAnalysis, run_analysis
from results_analysis.bradley_terry import BOOT_PRIOR
from results_analysis.document import Document
from results_analysis.objective_metrics import compare_metrics
from results_analysis.paradigm_analysis import stats_entry
from results_analysis.paradigm_report import add_sections, write_block_figures, write_block_tables
from results_analysis.posthoc import WILCOXON_EXACT_BELOW_N, nemenyi_q_alpha
from results_analysis.study_meta import relabel, with_criterion_label


def analyze(df: pd.DataFrame, out_dir: str | Path, *, title: str = "User study results",
            metrics: pd.DataFrame | None = None, **kwargs) -> Analysis:
    """Run :func:`results_analysis.analysis.run_analysis` on ``df`` and write every output into ``out_dir``.

    Keyword arguments are those of ``run_analysis`` (block, groups, questionnaire,
    exclude_failed_attention, exclude, alpha, conover, n_boot, ci, seed, incomplete, sm_permutations; for the
    pairwise, mismatch and rating blocks paradigm_n_boot, reference, screen_reference). Returns the
    :class:`Analysis`; the report is ``out_dir / "report.html"``. ``metrics``: a ``studyapp metrics`` table
    (:mod:`results_analysis.objective_metrics`), reported beside the mean ranks.
    """
    out = Path(out_dir)
    analysis = run_analysis(df, **kwargs)
    write_outputs(analysis, out, title=title, metrics=metrics)
    return analysis


def write_outputs(a: Analysis, out: Path, *, title: str, metrics: pd.DataFrame | None = None) -> None:
    """Write stats.json, tables, figures, report.md and report.html of an :class:`Analysis`.

    stats.json is keyed by condition ids (``_meta.labels`` maps them to their labels); the tables, figures and
    text show each condition's label (see :func:`results_analysis.study_meta.relabel`).
    """
    out.mkdir(parents=True, exist_ok=True)
    # the metrics CSV names conditions by id: join before relabelling
    objective = None if metrics is None else compare_metrics(metrics, {
        crit: dict(zip(c.summary["condition"], c.summary["mean_rank"])) for crit, c in a.criteria.items()},
        labels=a.labels, criterion_labels=a.criterion_labels)
    stats = stats_dict(a) | ({} if objective is None else {"_objective_metrics": objective.as_dict()})
    (out / "stats.json").write_text(json.dumps(_clean(stats), indent=2, allow_nan=False) + "\n")
    a = relabel(a, a.labels)
    write_tables(a, out / "tables")
    if a.criteria:  # the rank blocks' figures (a study of other paradigms only has none)
        write_figures(a, out / "figures")
    write_block_figures(a.paradigm_blocks, out / "figures", a.criterion_labels)
    doc = build_document(a, title)
    if objective is not None:
        objective.write_tables(out / "tables")
        objective.add_to(doc)
    (out / "report.md").write_text(doc.to_markdown() + "\n")
    (out / "report.html").write_text(doc.to_html(out / "figures"))


# --- stats.json ------------------------------------------------------------------------------------


def stats_dict(a: Analysis) -> dict:
    """The content of stats.json: one entry per criterion, plus ``_meta`` (and ``_groups``)."""
    out: dict = {}
    for crit, c in a.criteria.items():
        fr = c.friedman
        entry = {
            "block": a.block, "n_blocks": fr.n_blocks, "n_participants": int(np.unique(c.blocks.participants).size),
            "k": fr.k, "chi2": fr.chi2, "df": fr.df, "p": fr.p, "kendall_w": fr.kendall_w,
            "iman_davenport_f": fr.iman_davenport_f, "iman_davenport_df": [fr.iman_davenport_df1,
                                                                          fr.iman_davenport_df2],
            "iman_davenport_p": fr.iman_davenport_p, "tie_correction": fr.tie_correction,
            "mean_rank": dict(zip(a.conditions, fr.mean_rank)),
            "critical_difference": c.critical_difference, "alpha": a.alpha,
            "posthoc": {m: t.to_dict("records") for m, t in c.posthoc.items()},
            "conditions": c.summary.drop(columns=[]).to_dict("records"),
            "bradley_terry": c.bradley_terry.to_dict("records"),
        }
        if c.sensitivity is not None:
            s = c.sensitivity
            entry["sensitivity"] = {"block": c.sensitivity_block, "n_blocks": s.n_blocks, "chi2": s.chi2,
                                    "df": s.df, "p": s.p, "kendall_w": s.kendall_w,
                                    "mean_rank": dict(zip(a.conditions, s.mean_rank))}
        if c.skillings_mack is not None:
            sm = c.skillings_mack
            entry["skillings_mack"] = {"statistic": sm.statistic, "df": sm.df, "p": sm.p, "n_blocks": sm.n_blocks,
                                       "n_missing": sm.n_missing, "p_permutation": sm.p_permutation,
                                       "n_permutations": sm.n_permutations}
        entry.update(effects_report.criterion_stats(a, c))
        out[crit] = entry
    out["_meta"] = {
        "source": a.source, "block": a.block, "primary": f"Friedman test over {a.block}s",
        "ties": "answers turned into within-trial average ranks before every test; place shares split ties",
        "conditions": a.conditions, "labels": a.labels, "criteria": list(a.criteria),
        "criterion_labels": a.criterion_labels,
        "n_participants": a.n_participants, "n_trials": a.n_trials, "alpha": a.alpha,
        "excluded": a.exclusions.to_dict("records"), "incomplete_blocks": a.incomplete,
        "dropped_incomplete": a.dropped_incomplete, "incomplete_kept_for_skillings_mack": a.incomplete_blocks,
        "design_hashes": a.design_hashes, "warnings": a.warnings,
        "bootstrap": {"n_boot": a.n_boot, "seed": a.seed, "ci": a.ci, "resampled": "participants"},
        "wilcoxon": {"zero_method": "wilcox (zero differences dropped)",
                     "exact_if": f"fewer than {WILCOXON_EXACT_BELOW_N} non-zero differences, no ties and no "
                                 "zero differences (R's wilcox.test default)",
                     "otherwise": "normal approximation with tie and continuity correction",
                     "adjustment": a.adjust},
        "software": {"scipy": scipy.__version__, "numpy": np.__version__, "pandas": pd.__version__},
    }
    out["_meta"].update(effects_report.meta(a))
    if a.paradigm_blocks:
        out["_blocks"] = {k: stats_entry(b) for k, b in a.paradigm_blocks.items()}
    if a.groups:
        out["_groups"] = {g: t.to_dict("records") for g, t in a.groups.items()}
    if a.questionnaire_reliability is not None:
        out["_questionnaire"] = {"reliability": a.questionnaire_reliability.to_dict("records"),
                                 "items": a.questionnaire_items.to_dict("records"),
                                 "item_reliability": a.questionnaire_item_reliability.to_dict("records")}
    return out


def _clean(obj):
    """JSON-safe: numpy scalars to Python, NaN/inf to None."""
    if isinstance(obj, dict):
        return {str(k): _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    if isinstance(obj, (np.bool_, bool)):
        return bool(obj)
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        f = float(obj)
        return f if math.isfinite(f) else None
    return obj


# --- tables ----------------------------------------------------------------------------------------


def friedman_table(a: Analysis) -> pd.DataFrame:
    """One row per criterion: the test, its effect sizes, the CD and the sensitivity check."""
    rows = []
    for crit, c in a.criteria.items():
        fr, s = c.friedman, c.sensitivity
        rows.append({"criterion": crit, "block": a.block, "n_blocks": fr.n_blocks,
                     "n_participants": int(np.unique(c.blocks.participants).size), "k": fr.k,
                     "chi2": fr.chi2, "df": fr.df, "p": fr.p, "kendall_w": fr.kendall_w,
                     "iman_davenport_f": fr.iman_davenport_f, "id_df1": fr.iman_davenport_df1,
                     "id_df2": fr.iman_davenport_df2, "iman_davenport_p": fr.iman_davenport_p,
                     "critical_difference": c.critical_difference,
                     f"{c.sensitivity_block}_block_chi2": s.chi2 if s else np.nan,
                     f"{c.sensitivity_block}_block_p": s.p if s else np.nan,
                     f"{c.sensitivity_block}_block_w": s.kendall_w if s else np.nan})
    return pd.DataFrame(rows)


def write_tables(a: Analysis, out: Path) -> None:
    """Every CSV table of the analysis into ``out``. A table that names criteria keeps their ids in ``criterion``
    and has each one's label in ``criterion_label`` beside it (:func:`results_analysis.study_meta.with_criterion_label`)."""
    out.mkdir(parents=True, exist_ok=True)
    names = a.criterion_labels

    def csv(t: pd.DataFrame, name: str) -> None:
        with_criterion_label(t, names).to_csv(out / name, index=False)

    write_block_tables(a.paradigm_blocks, out, names)
    if a.criteria:  # the rank blocks' tables (a study of other paradigms only has none)
        csv(friedman_table(a), "friedman.csv")
        csv(pd.concat([c.summary.assign(criterion=k) for k, c in a.criteria.items()])[
            ["criterion"] + list(next(iter(a.criteria.values())).summary.columns)], "conditions.csv")
        methods = sorted({m for c in a.criteria.values() for m in c.posthoc})
        for m in methods:
            t = pd.concat([c.posthoc[m].assign(criterion=k) for k, c in a.criteria.items() if m in c.posthoc])
            csv(t[["criterion"] + [x for x in t.columns if x != "criterion"]], f"posthoc_{m}.csv")
        bt = pd.concat([c.bradley_terry.assign(criterion=k) for k, c in a.criteria.items()])
        csv(bt[["criterion"] + [x for x in bt.columns if x != "criterion"]], "bradley_terry.csv")
    a.exclusions.to_csv(out / "exclusions.csv", index=False)
    for g, t in a.groups.items():
        csv(t, f"by_{_safe(g)}.csv")
    if a.questionnaire_items is not None:
        a.questionnaire_items.to_csv(out / "questionnaire_items.csv", index=False)
        a.questionnaire_reliability.to_csv(out / "questionnaire_reliability.csv", index=False)
    effects_report.write_tables(a, out)


def _safe(name: str) -> str:
    return "".join(ch if ch.isalnum() or ch in "-_" else "_" for ch in name)


# --- figures ---------------------------------------------------------------------------------------


def display_order(a: Analysis) -> list[str]:
    """Conditions in the design's order (as in the tables; the same order and colours in every figure)."""
    return list(a.conditions)


def write_figures(a: Analysis, out: Path) -> None:
    # matplotlib is imported when the figures are drawn, not with the statistics (0.5-1 s of a cold start)
    from results_analysis import figures

    order = display_order(a)
    # panels are titled by the dicts' keys: the criteria's labels
    summaries = {a.criterion_name(k): c.summary for k, c in a.criteria.items()}
    figures.save(figures.rank_share_figure(summaries, order), out, "rank_shares")
    cd_input = {a.criterion_name(k): (dict(zip(a.conditions, c.friedman.mean_rank)), c.critical_difference)
                for k, c in a.criteria.items()}
    figures.save(figures.cd_diagram(cd_input, alpha=a.alpha, order=order, rank_name=(
        "Friedman mean rank: each participant's mean ranks ranked again" if a.block == "participant"
        else "Mean rank over trials")), out, "critical_difference")
    figures.save(figures.mean_rank_figure(summaries, order, ci=a.ci), out, "mean_ranks")
    figures.save(figures.bt_figure({a.criterion_name(k): c.bradley_terry for k, c in a.criteria.items()}, order,
                                   ci=a.ci), out, "bradley_terry")


# --- the report text -------------------------------------------------------------------------------


def fmt_p(p: float, *, adjusted: bool = False) -> str:
    """APA style: ``p < .001`` or ``p = .023`` (``p_adj`` when adjusted).

    >>> fmt_p(0.0004), fmt_p(0.02349), fmt_p(0.5)
    ('p < .001', 'p = .023', 'p = .500')
    """
    name = "p_adj" if adjusted else "p"
    if p is None or not np.isfinite(p):
        return f"{name} = n/a"
    if p < 0.001:
        return f"{name} < .001"
    return f"{name} = {p:.3f}".replace("0.", ".", 1)


def _p_cell(p: float) -> str:
    """A p value for a table cell: ``< .001`` or ``.023``."""
    return fmt_p(p).split(" ", 1)[1].lstrip("= ")


# Every statistic printed in both the prose and a report table goes through one of these formatters in both
# places, so a reader never sees 50 in the text and 49.5 in the table for the same number.


def _num(v: float, digits: int = 2) -> str:
    """A statistic (χ², W, F, CD, mean rank, r_rb, ...) with ``digits`` decimals; ``n/a`` when undefined.

    >>> _num(83.6354), _num(float("nan")), _num(float("inf"))
    ('83.64', 'n/a', '∞')
    """
    if v is None or not np.isfinite(v):
        return "∞" if v is not None and np.isposinf(v) else "n/a"
    return f"{v:.{digits}f}"


def fmt_v(v: float) -> str:
    """The Wilcoxon V (a sum of signed ranks: a whole or half number with tied ranks) as R prints it: an
    integer when it is one, otherwise one decimal; never rounded to a neighbouring integer.

    >>> fmt_v(49.5), fmt_v(236.0), fmt_v(235.49999999999997), fmt_v(1234567.0), fmt_v(float("nan"))
    ('49.5', '236', '235.5', '1234567', 'n/a')
    """
    if v is None or not np.isfinite(v):
        return "n/a"
    r = round(float(v), 1)
    return f"{r:.0f}" if r == int(r) else f"{r:.1f}"


def _alpha(x: float) -> str:
    return f"{x:g}".replace("0.", ".", 1)


def criterion_paragraphs(a: Analysis, c: CriterionAnalysis) -> list[str]:
    """The results-section text of one criterion."""
    fr = c.friedman
    k = fr.k
    n_part = int(np.unique(c.blocks.participants).size)
    s = c.summary.set_index("condition")
    order = sorted(a.conditions, key=lambda x: s.loc[x, "mean_rank"])
    ci = f"{a.ci:.0%}"
    ranks = ", ".join(f"{x} {_num(s.loc[x, 'mean_rank'])} ({ci} CI {_num(s.loc[x, 'ci_low'])}–"
                      f"{_num(s.loc[x, 'ci_high'])}; ranked first in {s.loc[x, 'share_rank_1']:.0%})" for x in order)
    headline = (f"The primary, participant-level Friedman test (each of the {fr.n_blocks} participants a block, "
                f"valued by their mean within-trial rank per condition)" if a.block == "participant" else
                f"The trial-level Friedman test (each of the {fr.n_blocks} trials from {n_part} participants a "
                f"block, as published analyses count them)")
    sig = fr.p < a.alpha
    verdict = "showed a significant difference between" if sig else "did not show a significant difference between"
    text = [f"**{a.criterion_name(c.criterion)}.** Mean ranks (1 = best) were {ranks}. {headline} "
            f"{verdict} the {k} conditions, χ²({fr.df}) = {_num(fr.chi2)}, {fmt_p(fr.p)}, Kendall's W = "
            f"{effects_report.kendall_w_text(a, c)} (Iman–Davenport F({fr.iman_davenport_df1}, {fr.iman_davenport_df2}) = "
            f"{_num(fr.iman_davenport_f)}, {fmt_p(fr.iman_davenport_p)})."]
    if c.sensitivity is not None:
        sv = c.sensitivity
        agree = "agreed" if (sv.p < a.alpha) == sig else "disagreed"
        stat = f"χ²({sv.df}) = {_num(sv.chi2)}, {fmt_p(sv.p)}, W = {_num(sv.kendall_w)}, n = {sv.n_blocks}"
        if c.sensitivity_block == "trial":
            text[0] += (f" The secondary, trial-level test (every trial a block) {agree}: {stat}; it counts a "
                        "participant's trials as independent blocks (pseudo-replication), so its p-value "
                        "overstates the evidence.")
        else:
            text[0] += (f" The participant-level test (each participant's mean within-trial rank per condition a "
                        f"block), which respects the repeated measures, {agree}: {stat}.")
    if c.skillings_mack is not None:
        sm = c.skillings_mack
        text[0] += (f" Including the incomplete trials ({sm.n_missing} missing rank(s) over {sm.n_blocks} trials), the "
                    f"Skillings–Mack test gave SM({sm.df}) = {_num(sm.statistic)}, {fmt_p(sm.p)} (χ² approximation)")
        if sm.p_permutation is not None:
            text[0] += (f"; a permutation test with {sm.n_permutations} within-trial shuffles gave "
                        f"{fmt_p(sm.p_permutation)}")
        text[0] += "."
    nem = c.posthoc["nemenyi"]
    parts = []
    for r in nem.itertuples():
        better, worse = (r.a, r.b) if r.mean_rank_a < r.mean_rank_b else (r.b, r.a)
        if r.significant:
            parts.append(f"{better} was ranked better than {worse} (difference {_num(r.difference)}, "
                         f"{fmt_p(r.p_adjusted, adjusted=True)})")
        else:
            parts.append(f"{better} and {worse} were not separated (difference {_num(r.difference)}, "
                         f"{fmt_p(r.p_adjusted, adjusted=True)})")
    lead = "Nemenyi post-hoc tests" if sig else "For completeness only (the omnibus test was not significant), Nemenyi tests"
    post = (f"{lead} (critical difference CD = {_num(c.critical_difference)} at α = {_alpha(a.alpha)}) found: "
            + "; ".join(parts) + ".")
    wil = c.posthoc["wilcoxon_holm"]
    wparts = [f"{r.a} vs {r.b}: V = {fmt_v(r.statistic)}, r_rb = {_num(r.rank_biserial)}, "
              f"{fmt_p(r.p_adjusted, adjusted=True)}" for r in wil.itertuples()]
    # Name the pairs where the two post-hoc families disagree: a reader must not have to find them.
    nem_sig = {frozenset((r.a, r.b)): bool(r.significant) for r in nem.itertuples()}
    differ = [f"{w.a} vs {w.b} (significant only with {'Wilcoxon' if w.p_adjusted < a.alpha else 'Nemenyi'})"
              for w in wil.itertuples() if (w.p_adjusted < a.alpha) != nem_sig[frozenset((w.a, w.b))]]
    methods = sorted(set(wil["method"]))
    verdict = ("led to the same conclusions" if not differ else
               "agreed with the Nemenyi tests except for " + " and ".join(differ))
    post += (f" Pairwise Wilcoxon signed-rank tests"
             + (f" against the control {a.control}" if a.control is not None else "")
             + f" with {effects_report.adjustment_name(a)} adjustment ({', '.join(methods)}) {verdict}: "
             + "; ".join(wparts) + ".")
    if "conover" in c.posthoc:
        con = c.posthoc["conover"]
        post += (f" Conover's post-hoc tests (t distribution, {effects_report.adjustment_name(a)}): "
                 + "; ".join(f"{r.a} vs {r.b}: t({r.df}) = {_num(r.statistic)}, {fmt_p(r.p_adjusted, adjusted=True)}"
                             for r in con.itertuples()) + ".")
    text.append(post)
    bt = c.bradley_terry.set_index("condition")
    text.append("Bradley–Terry strengths from the pairwise preferences implied by the rankings: " + ", ".join(
        f"{x} {_bt_cell(bt.loc[x], ci)}" for x in order) + ".")
    return text


def _bt_cell(row: pd.Series, ci: str | None = None) -> str:
    """A Bradley-Terry strength with its interval, or why it has none (never a made-up 0.00)."""
    if "estimable" in row.index and not bool(row["estimable"]):
        return f"not estimable ({row['note']})"
    ci = f"{ci} CI " if ci else ""
    interval = (f" ({ci}{_num(row['ci_low'])}–{_num(row['ci_high'])})" if np.isfinite(row["ci_low"]) else "")
    return f"{_num(row['strength'])}{interval}"


def methods_paragraph(a: Analysis) -> str:
    k = len(a.conditions)
    excl = ("No participant was excluded." if a.exclusions.empty else
            f"{len(a.exclusions)} participant(s) were excluded: " +
            "; ".join(f"{r.participant} ({r.reason})" for r in a.exclusions.itertuples()) + ".")
    block = ("each trial (one participant ranking the conditions for one stimulus) as a block, as the published "
             "analyses this replicates did"
             if a.block == "trial" else
             "each participant as a block, using the participant's mean within-trial rank per condition over their "
             "trials (the primary analysis: a participant's trials are repeated measures of one person, so only "
             "participants are independent blocks)")
    sens = ("As a check that respects the repeated measures, the test was repeated with participants as blocks "
            "(mean within-trial rank per participant and condition, re-ranked within participant)."
            if a.block == "trial" else
            "As a secondary analysis the test was repeated with single trials as blocks; it treats a "
            "participant's trials as independent observations (pseudo-replication), so its p-values are too "
            "small and it is reported only for comparison with published trial-level analyses.")
    if a.incomplete == "error":
        incomplete = "Every analysed trial ranked every condition (incomplete trials would have stopped the analysis)."
    elif a.incomplete == "drop":
        incomplete = (f"Trials that did not rank every condition were removed (listwise deletion; "
                      f"{a.dropped_incomplete} trial-criterion block(s) removed); no Skillings–Mack test was used.")
    else:
        incomplete = (f"{a.incomplete_blocks} trial-criterion block(s) did not rank every condition: the Skillings–Mack "
                      "test (missing ranks set to the block's mean rank, generalised-inverse covariance, χ²(k−1)"
                      + (", and a Monte Carlo permutation p-value from "
                         f"{a.sm_permutations} shuffles of the ranks within each trial, seed {a.seed}"
                         if a.sm_permutations else "") +
                      ") was computed over all trials, and the Friedman, post-hoc and descriptive statistics over "
                      "the complete trials (listwise deletion).")
    return (
        f"Practice trials and attention-check (catch) trials were not analysed. {excl} The analysis covers "
        f"{a.n_participants} participants and {a.n_trials} trials. For each criterion, the {k} conditions were "
        f"compared with a Friedman test with {block}. Every answer was first turned into average ranks within "
        f"its trial (a tie for first of two conditions becomes 1.5, 1.5), so every test and effect size is "
        f"the same however ties were written; the Friedman statistic was corrected for ties. Effect size is "
        f"Kendall's W = χ²/(n(k−1)); the Iman–Davenport statistic "
        f"F = (n−1)χ²/(n(k−1)−χ²) with ({k - 1}, {k - 1}(n−1)) degrees of freedom is also reported. {sens} "
        f"Post-hoc, mean ranks were compared with the Nemenyi single-step test (studentized range with infinite "
        f"degrees of freedom; critical difference CD = q_α/√2 · √(k(k+1)/(6n)), q_α/√2 = "
        f"{nemenyi_q_alpha(k, a.alpha):.3f} for k = {k} at α = {_alpha(a.alpha)}), and with two-sided Wilcoxon "
        f"signed-rank tests on the paired block values (within-trial ranks, or a participant's mean of them), "
        f"{effects_report.adjustment_name(a)}-adjusted over the {effects_report.n_comparisons(a)} comparisons; zero "
        f"differences were discarded (Wilcoxon's method) and, as in R's wilcox.test, the exact null "
        f"distribution was used only when fewer than {WILCOXON_EXACT_BELOW_N} non-zero differences remained and "
        f"there were neither ties nor zero differences, otherwise the normal approximation with tie and "
        f"continuity correction. Effect size of a pair is the matched-pairs rank-biserial correlation "
        f"r_rb (positive: the first condition received larger, i.e. worse, ranks). Mean ranks come with "
        f"{a.ci:.0%} percentile bootstrap intervals ({a.n_boot} resamples of participants, seed {a.seed}), which "
        f"keeps each participant's trials together. The share of answers at each place splits a tied answer "
        f"between the places it spans (half to each place of a two-way tie, a third each for a three-way tie), "
        f"so each condition's shares sum to 100 %. Bradley–Terry strengths were fitted by maximum likelihood "
        f"(Newton's method to convergence) to the pairwise wins implied by each ranking (ties: half a win each), "
        f"with {a.n_boot // 2} participant bootstrap resamples (a pseudo-count of {BOOT_PRIOR:g} wins per pair "
        f"keeps a resample finite); a condition that never won or never lost has no finite strength and is "
        f"reported as not estimable. {incomplete} {effects_report.methods_text(a)} Computed with results_analysis "
        f"(scipy {scipy.__version__}).")


def _percentages(shares: list[float]) -> list[str]:
    """Whole percentages of shares that sum to 1, rounded so the printed row sums to 100 % too (largest
    remainder: rounding each alone can print 12 + 83 + 4 = 99).

    >>> _percentages([0.125, 0.8333333, 0.0416667])
    ['13%', '83%', '4%']
    """
    raw = [100.0 * float(x) if np.isfinite(x) else 0.0 for x in shares]
    whole = [int(np.floor(v)) for v in raw]
    if abs(sum(raw) - 100.0) < 1e-6:  # shares of all places: hand out the missing points by remainder
        for i in sorted(range(len(raw)), key=lambda i: raw[i] - whole[i], reverse=True)[:100 - sum(whole)]:
            whole[i] += 1
    else:
        whole = [int(round(v)) for v in raw]
    return [f"{w}%" for w in whole]


def build_document(a: Analysis, title: str) -> Document:
    doc = Document(title)
    if a.warnings:
        doc.h(1, "Warnings")
        doc.items(a.warnings)
    if a.criteria:  # the rank blocks (a study of other paradigms only has none)
        doc.h(1, "Method")
        doc.p(methods_paragraph(a))
        doc.h(1, "Results")
        for c in a.criteria.values():
            for para in criterion_paragraphs(a, c):
                doc.p(para)
        ft = friedman_table(a)
        show = ft[["criterion", "n_blocks", "chi2", "df", "p", "kendall_w", "iman_davenport_f", "iman_davenport_p",
                   "critical_difference"]].rename(columns={"n_blocks": "n", "chi2": "χ²", "kendall_w": "W",
                                                           "iman_davenport_f": "F_ID", "iman_davenport_p": "p (F_ID)",
                                                           "critical_difference": "CD"})
        show["criterion"] = show["criterion"].map(a.criterion_name)
        show["p"] = [_p_cell(p) for p in show["p"]]
        show["p (F_ID)"] = [_p_cell(p) for p in show["p (F_ID)"]]
        for col in ("χ²", "W", "F_ID", "CD"):
            show[col] = [_num(v) for v in show[col]]
        doc.table(show, "Table 1. Friedman tests per criterion (" + (
            "primary analysis, blocks: participants" if a.block == "participant" else "blocks: trials") + ").")
        rows = []
        for crit, c in a.criteria.items():
            for r in c.summary.itertuples():
                rows.append({"criterion": a.criterion_name(crit), "condition": r.condition, "n": r.n,
                             "mean rank": _num(r.mean_rank),
                             f"{a.ci:.0%} CI": f"{_num(r.ci_low)}–{_num(r.ci_high)}", "median": f"{r.median_rank:g}",
                             **dict(zip((f"rank {i}" for i in range(1, len(a.conditions) + 1)), _percentages(
                                 [getattr(r, f"share_rank_{i}") for i in range(1, len(a.conditions) + 1)])))})
        doc.table(pd.DataFrame(rows), "Table 2. Ranks per condition (1 = best): mean over all answers with "
                  "participant-bootstrap interval, median, and share of answers at each rank (a tied answer shared between the places it "
                  "spans, so each row sums to 100 %).")
        doc.table(effects_report.posthoc_table(a), effects_report.posthoc_caption(a))
        btrows = [{"criterion": a.criterion_name(crit), "condition": r["condition"], "strength": _bt_cell(r),
                   "win rate": f"{r['win_rate']:.0%}"} for crit, c in a.criteria.items()
                  for _, r in c.bradley_terry.iterrows()]
        doc.table(pd.DataFrame(btrows), f"Table 4. Bradley–Terry strengths (sum to 1) with {a.ci:.0%} participant-"
                  "bootstrap interval; a condition that never won or never lost has no finite strength.")
        doc.figure("rank_shares", "Figure 1. Share of answers at each rank, per condition and criterion (ties shared "
                   "between the places they span).")
        doc.figure("critical_difference", f"Figure 2. Critical-difference diagrams (Nemenyi, α = {_alpha(a.alpha)}): "
                   "conditions joined by a bar are not significantly different." + (
                       " Positions are the Friedman test's mean ranks: each participant's mean rank per condition, "
                       "ranked again within the participant, averaged over participants; they can differ from "
                       "Table 2's mean over all answers." if a.block == "participant" else ""))
        doc.figure("mean_ranks", f"Figure 3. Mean rank with {a.ci:.0%} participant-bootstrap interval.")
        doc.figure("bradley_terry", f"Figure 4. Bradley–Terry strengths with {a.ci:.0%} participant-bootstrap interval.")
        effects_report.agreement_section(a, doc)
    add_sections(a.paradigm_blocks, doc, a.criterion_labels)
    if a.groups:
        doc.h(1, "Breakdowns")
        for g, t in a.groups.items():
            cols = ["level", "criterion", "n_blocks", "n_participants", "chi2", "p", "kendall_w"] + \
                   [f"mean_rank_{x}" for x in a.conditions]
            show = t[cols].rename(columns={"n_blocks": "n", "n_participants": "participants", "chi2": "χ²",
                                           "kendall_w": "W", **{f"mean_rank_{x}": f"mean rank {x}" for x in a.conditions}})
            show["criterion"] = show["criterion"].map(a.criterion_name)
            show["p"] = [_p_cell(p) for p in show["p"]]
            # Same precision as Tables 1 and 2, so a level's numbers compare directly with the overall ones.
            for col in ["χ²", "W"] + [f"mean rank {x}" for x in a.conditions]:
                show[col] = [_num(v) for v in show[col]]
            doc.table(show, f"Friedman test per level of '{g}' (blocks: {a.block}s).")
    if a.questionnaire_reliability is not None:
        doc.h(1, "Questionnaire")
        doc.p(effects_report.reliability_text(a))
        doc.table(a.questionnaire_items, "Questionnaire items.")
        effects_report.item_reliability_table(a, doc)
    doc.h(1, "Exclusions")
    if a.exclusions.empty:
        doc.p("No participant was excluded. Practice trials and attention-check trials are never analysed.")
    else:
        doc.table(a.exclusions, "Excluded participants and why. Practice and attention-check trials are never analysed.")
    if len(a.attention):
        failed = a.attention[a.attention["failed"] > 0]
        doc.p(f"{len(a.attention)} participants saw {int(a.attention['checks'].sum())} attention-check trials; "
              f"{len(failed)} failed at least one"
              + (" (excluded with --exclude-failed-attention)." if a.exclusions["reason"].str.contains("attention").any()
                 else " (kept: --exclude-failed-attention was not used)." if len(failed) else "."))
        if len(failed):
            doc.table(failed, "Participants who failed attention checks.")
    return doc
