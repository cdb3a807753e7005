"""The report's parts for effect-size intervals, the p-value adjustment, comparisons against a control,
agreement between participants per stimulus and questionnaire reliability: their stats.json entries,
tables (CSV and report tables) and method sentences. ``report`` calls these; every number printed goes
through report's formatters, so the text and the tables agree.
"""
from __future__ import annotations

from pathlib import Path

import pandas as pd

from results_analysis.adjust import ADJUSTMENT_CONTROLS, ADJUSTMENT_NAMES
from results_analysis.analysis import Analysis, CriterionAnalysis
from results_analysis.bootstrap import INTERVAL_NAMES
from results_analysis.document import Document
from results_analysis.posthoc import WILCOXON_EXACT_BELOW_N
from results_analysis.study_meta import with_criterion_label


def adjustment_name(a: Analysis) -> str:
    return ADJUSTMENT_NAMES[a.adjust]


def n_comparisons(a: Analysis) -> int:
    k = len(a.conditions)
    return k - 1 if a.control is not None else k * (k - 1) // 2


# --- stats.json --------------------------------------------------------------------------------------


def criterion_stats(a: Analysis, c: CriterionAnalysis) -> dict:
    """Entries added to a criterion of stats.json: effect sizes with intervals and the agreement per stimulus."""
    out: dict = {}
    if c.effect_sizes is not None:
        out["effect_sizes"] = {"kendall_w": c.effect_sizes.kendall_w.iloc[0].to_dict(),
                               "pairs": c.effect_sizes.pairs.to_dict("records")}
    if a.agreement is not None:
        out["agreement"] = {
            "per_stimulus": a.agreement[a.agreement["criterion"] == c.criterion].drop(columns="criterion")
            .to_dict("records"),
            "summary": next(iter(a.agreement_summary[a.agreement_summary["criterion"] == c.criterion]
                                 .drop(columns="criterion").to_dict("records")), {})}
    return out


def meta(a: Analysis) -> dict:
    """Entries added to stats.json's ``_meta``."""
    return {"adjustment": {"method": a.adjust, "name": adjustment_name(a), "controls": ADJUSTMENT_CONTROLS[a.adjust],
                           "n_comparisons": n_comparisons(a)},
            "control": a.control,
            "effect_size_intervals": {"bootstrap": INTERVAL_NAMES[a.interval], "n_boot": a.n_boot, "seed": a.seed,
                                      "ci": a.ci, "resampled": "participants",
                                      "hodges_lehmann": ("distribution-free (inverted Wilcoxon test, R's "
                                                         "wilcox.test conf.int)" if a.block == "participant"
                                                         else "participant bootstrap")},
            "questionnaire_interval": "Feldt"}


# --- tables ------------------------------------------------------------------------------------------


def write_tables(a: Analysis, out: Path) -> None:
    """effect_sizes.csv, kendall_w.csv, agreement.csv, agreement_summary.csv and
    questionnaire_item_reliability.csv in ``out``."""
    def csv(t: pd.DataFrame, name: str) -> None:  # criteria by id, and by label beside it
        with_criterion_label(t, a.criterion_labels).to_csv(out / name, index=False)

    eff = [c.effect_sizes for c in a.criteria.values() if c.effect_sizes is not None]
    if eff:
        csv(pd.concat([e.pairs.assign(criterion=k) for k, e in zip(a.criteria, eff)])[
            ["criterion"] + list(eff[0].pairs.columns)], "effect_sizes.csv")
        csv(pd.concat([e.kendall_w.assign(criterion=k) for k, e in zip(a.criteria, eff)])[
            ["criterion"] + list(eff[0].kendall_w.columns)], "kendall_w.csv")
    if a.agreement is not None:
        csv(a.agreement, "agreement.csv")
        csv(a.agreement_summary, "agreement_summary.csv")
    if a.questionnaire_item_reliability is not None:
        a.questionnaire_item_reliability.to_csv(out / "questionnaire_item_reliability.csv", index=False)


def _interval(lo: float, hi: float) -> str:
    """'0.21–0.60', or '−0.19 to 0.91' when an end is negative (a dash would read as a minus sign)."""
    from results_analysis.report import _num

    if min(lo, hi) < 0:
        return f"{_num(lo)} to {_num(hi)}".replace("-", "−")
    return f"{_num(lo)}–{_num(hi)}"


def kendall_w_text(a: Analysis, c: CriterionAnalysis) -> str:
    """``Kendall's W`` with its interval, for the results sentence: '0.42 (95% CI 0.21–0.60)'."""
    from results_analysis.report import _num

    if c.effect_sizes is None:
        return _num(c.friedman.kendall_w)
    w = c.effect_sizes.kendall_w.iloc[0]
    return f"{_num(c.friedman.kendall_w)} ({a.ci:.0%} CI {_interval(w['ci_low'], w['ci_high'])})"


def posthoc_table(a: Analysis) -> pd.DataFrame:
    """Table 3 rows: one per Wilcoxon comparison (all pairs, or against the control), with the Nemenyi
    difference and p of the same pair, V, r_rb and Hodges-Lehmann with their intervals and the adjusted p."""
    from results_analysis.report import _num, _p_cell, fmt_v

    ci = f"{a.ci:.0%} CI"
    rows = []
    for crit, c in a.criteria.items():
        nem = {frozenset((r.a, r.b)): r for r in c.posthoc["nemenyi"].itertuples()}
        eff = c.effect_sizes.pairs.set_index(["a", "b"]) if c.effect_sizes is not None else None
        for w in c.posthoc["wilcoxon_holm"].itertuples():
            n = nem[frozenset((w.a, w.b))]
            row = {"criterion": a.criterion_name(crit), "pair": f"{w.a} – {w.b}",
                   "Δ mean rank": _num(n.difference),
                   "Nemenyi p_adj": _p_cell(n.p_adjusted), "Wilcoxon V": fmt_v(w.statistic),
                   "r_rb": _num(w.rank_biserial)}
            if eff is not None:
                e = eff.loc[(w.a, w.b)]
                row[f"r_rb {ci}"] = _interval(e["rb_ci_low"], e["rb_ci_high"])
                row["HL"] = _num(e["hodges_lehmann"])
                # an exact interval's level is what the signed-rank distribution allows (e.g. 96.1 %), and R
                # widens a normal one for very few blocks: say so where it differs from the level asked for
                level = e["hl_conf_level"]
                row[f"HL {ci}"] = _interval(e["hl_ci_low"], e["hl_ci_high"]) + (
                    f" (at {level:.1%})" if level == level and abs(level - a.ci) > 5e-4 else "")
            row[f"Wilcoxon p_adj ({adjustment_name(a)})"] = _p_cell(w.p_adjusted)
            row["method"] = w.method
            rows.append(row)
    return pd.DataFrame(rows)


def posthoc_caption(a: Analysis) -> str:
    which = (f"each condition against the control {a.control} ({n_comparisons(a)} comparisons)"
             if a.control is not None else f"all {n_comparisons(a)} pairs")
    hl = ("distribution-free interval from the Wilcoxon test" if a.block == "participant"
          else f"{INTERVAL_NAMES[a.interval]} participant-bootstrap interval")
    delta = ("difference of the Friedman test's mean ranks, as placed in Figure 2" if a.block == "participant"
             else "difference of mean ranks")
    return (f"Table 3. Post-hoc comparisons, {which} (Δ: {delta}; r_rb: matched-pairs "
            f"rank-biserial correlation of the Wilcoxon test with its {INTERVAL_NAMES[a.interval]} "
            f"participant-bootstrap interval; HL: Hodges–Lehmann estimate of the difference of ranks, first "
            f"minus second, with its {hl}; Wilcoxon p-values adjusted by {adjustment_name(a)} over the "
            f"{n_comparisons(a)} comparisons).")


# --- method text -------------------------------------------------------------------------------------


def methods_text(a: Analysis) -> str:
    """Sentences for the method paragraph: adjustment, control, effect-size intervals, agreement and the
    questionnaire's reliability."""
    ci = f"{a.ci:.0%}"
    boot = INTERVAL_NAMES[a.interval]
    parts = []
    if a.control is not None:
        parts.append(f"Post-hoc Wilcoxon{' and Conover' if a.conover else ''} tests compared each condition with "
                     f"the control condition {a.control} only ({n_comparisons(a)} comparisons), and their p-values "
                     f"were adjusted over these {n_comparisons(a)} comparisons; the Nemenyi test and its critical "
                     "difference still cover all pairs.")
    parts.append(f"The {adjustment_name(a)} adjustment controls the {ADJUSTMENT_CONTROLS[a.adjust]}.")
    parts.append(
        f"Kendall's W and each pair's r_rb come with {ci} {boot} bootstrap intervals ({a.n_boot} resamples of "
        f"participants, seed {a.seed}; "
        + ("bias-corrected and accelerated, the acceleration from the leave-one-participant-out jackknife; the "
           "percentile interval where BCa is undefined" if a.interval == "bca" else "percentile interval") + "). "
        "The Hodges–Lehmann estimate of a pair is the median of the Walsh averages of the non-zero paired "
        "differences of block values (zeros dropped, as in the Wilcoxon test), "
        + (f"with the distribution-free interval that inverts the Wilcoxon test (R's wilcox.test with "
           f"conf.int): exact from the signed-rank distribution when fewer than {WILCOXON_EXACT_BELOW_N} non-zero "
           "differences remain with neither ties nor zeros (its achieved level is reported), otherwise the normal "
           "approximation with tie and continuity correction." if a.block == "participant" else
           f"with a {boot} bootstrap interval over participants (the Wilcoxon-based interval assumes independent "
           "blocks, which a participant's trials are not)."))
    parts.append(
        "Agreement between participants was measured per stimulus and criterion by Kendall's coefficient of "
        "concordance W over the participants who ranked that stimulus (a participant's repeated answers averaged), "
        f"corrected for ties, with its χ²(k−1) = m(k−1)W test, p-values {adjustment_name(a)}-adjusted over the "
        "stimuli of a criterion.")
    if a.questionnaire_reliability is not None:
        parts.append(f"Cronbach's α of each questionnaire scale comes with Feldt's {ci} interval (F "
                     "distribution with n−1 and (n−1)(k−1) degrees of freedom), and each item with the α of the "
                     "scale without it and its corrected item-total correlation.")
    return " ".join(parts)


# --- report sections ---------------------------------------------------------------------------------


def agreement_section(a: Analysis, doc: Document) -> None:
    """The 'Agreement between participants' section: the summary per criterion and the per-stimulus table."""
    from results_analysis.report import _num, _p_cell

    if a.agreement is None or a.agreement.empty:
        return
    doc.h(1, "Agreement between participants")
    s = a.agreement_summary
    doc.p("Per stimulus, Kendall's W measures how similarly the participants who ranked it ordered the "
          "conditions (0: no agreement, 1: identical rankings). " + "; ".join(
              f"{a.criterion_name(r.criterion)}: median W = {_num(r.median_w)} over {r.n_stimuli} stimuli (range "
              f"{_num(r.min_w)}–{_num(r.max_w)}, {_num(r.mean_raters, 1)} participants per stimulus on average), "
              f"significant concordance for {r.n_significant} of {r.n_stimuli}" for r in s.itertuples()) + ".")
    t = a.agreement.copy()
    show = pd.DataFrame({"criterion": t["criterion"].map(a.criterion_name), "stimulus": t["stimulus"],
                         "participants": t["n_raters"],
                         "W": [_num(v) for v in t["kendall_w"]], "χ²": [_num(v) for v in t["chi2"]], "df": t["df"],
                         "p": [_p_cell(v) for v in t["p"]],
                         f"p_adj ({adjustment_name(a)})": [_p_cell(v) for v in t["p_adjusted"]]})
    doc.table(show, "Table 5. Agreement between participants per stimulus (Kendall's W with tie correction, "
              f"χ² test on k−1 df, p-values adjusted by {adjustment_name(a)} over the stimuli of a criterion).")


def reliability_text(a: Analysis) -> str:
    """The questionnaire's reliability sentence, with Feldt's intervals."""
    from results_analysis.report import _num

    rel = a.questionnaire_reliability
    ci = f"{a.ci:.0%}"
    return ("Internal consistency per scale (Cronbach's α with Feldt's interval; participants who answered every "
            "item of the scale; α ≥ 0.7 is conventionally taken as acceptable): " + "; ".join(
                f"{r.scale}: α = {_num(r.alpha)} ({ci} CI {_interval(r.ci_low, r.ci_high)}; {r.n_items} items, "
                f"{r.n_participants} participants"
                + (", below 0.7: the items do not form a reliable scale" if r.alpha == r.alpha and r.alpha < 0.7
                   else "") + ")"
                for r in rel.itertuples()) + ".")


def item_reliability_table(a: Analysis, doc: Document) -> None:
    from results_analysis.report import _num

    t = a.questionnaire_item_reliability
    if t is None or t.empty:
        return
    doc.table(pd.DataFrame({"scale": t["scale"], "item": t["item"],
                            "α if dropped": [_num(v) for v in t["alpha_if_dropped"]],
                            "item-rest r": [_num(v) for v in t["r_drop"]]}),
              "Questionnaire items: the scale's α without the item, and the item's correlation with the sum of "
              "the other items.")
