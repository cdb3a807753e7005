"""The report's part for the pairwise, mismatch and rating blocks: one section per block with its paradigm's
method, results text, tables (``tables/block_<id>_*.csv``) and figures (``figures/block_<id>_*.png|svg``, each
drawn once).

It reads a relabelled :class:`results_analysis.analysis.Analysis` (conditions shown by their labels);
stats.json gets the numbers under condition ids from :func:`results_analysis.paradigm_analysis.stats_entry`.
"""
from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np
import pandas as pd

from results_analysis.bradley_terry import BOOT_PRIOR
from results_analysis.document import Document
from results_analysis.paradigm_analysis import BlockAnalysis, MismatchResult, PairwiseResult, RatingResult, n_boot_note
from results_analysis.posthoc import WILCOXON_EXACT_BELOW_N
from results_analysis.study_meta import with_criterion_label


def _safe(name: str) -> str:
    return "".join(ch if ch.isalnum() or ch in "-_" else "_" for ch in str(name))


def _stem(b: BlockAnalysis) -> str:
    return f"block_{_safe(b.block)}"


def _of(b: BlockAnalysis, kind: type) -> dict:
    return {c: r for c, r in b.results.items() if isinstance(r, kind)}


# --- tables -------------------------------------------------------------------------------------------


def _concat(parts: dict[str, pd.DataFrame]) -> pd.DataFrame:
    t = pd.concat([df.assign(criterion=c) for c, df in parts.items()], ignore_index=True)
    return t[["criterion"] + [x for x in t.columns if x != "criterion"]]


def block_tables(b: BlockAnalysis) -> dict[str, pd.DataFrame]:
    """The CSV tables of one block, by file name stem.

    >>> from results_analysis.paradigm_analysis import analyze_block
    >>> from results_analysis.simulate import simulate_paradigm
    >>> b = analyze_block(simulate_paradigm("mismatch", 6, 3, block="m", seed=1), "m", "mismatch", n_boot=0)
    >>> sorted(block_tables(b))
    ['block_m_mismatch', 'block_m_mismatch_comparisons']
    """
    s = _stem(b)
    out: dict[str, pd.DataFrame] = {}
    if b.paradigm == "pairwise":
        res = _of(b, PairwiseResult)
        out[f"{s}_elo"] = _concat({c: r.elo for c, r in res.items()})
        out[f"{s}_wins"] = _concat({c: r.wins for c, r in res.items()})
        out[f"{s}_elo_differences"] = _concat({c: r.differences for c, r in res.items()})
        if any(len(r.reasons) for r in res.values()):
            out[f"{s}_reasons"] = _concat({c: r.reasons for c, r in res.items()})
    elif b.paradigm == "mismatch":
        res = _of(b, MismatchResult)
        out[f"{s}_mismatch"] = _concat({c: r.rates for c, r in res.items()})
        out[f"{s}_mismatch_comparisons"] = _concat({c: r.comparisons for c, r in res.items()})
    else:
        res = _of(b, RatingResult)
        out[f"{s}_ratings"] = _concat({c: r.summary for c, r in res.items()})
        out[f"{s}_rating_friedman"] = _concat({c: r.friedman.reset_index(drop=True) for c, r in res.items()})
        out[f"{s}_rating_wilcoxon"] = _concat({c: r.posthoc for c, r in res.items()})
        if b.screening is not None:
            out[f"{s}_screening"] = b.screening
    return out


def write_block_tables(blocks: dict[str, BlockAnalysis], out: Path, names: Mapping[str, str] | None = None) -> None:
    """Every block's :func:`block_tables` as ``out/<stem>.csv``; a table's ``criterion`` column (ids) gets each
    criterion's name in ``names`` (id -> label; default: the id) beside it, as ``criterion_label``."""
    out.mkdir(parents=True, exist_ok=True)
    for b in blocks.values():
        for name, t in block_tables(b).items():
            with_criterion_label(t, names or {}).to_csv(out / f"{name}.csv", index=False)


# --- figures ------------------------------------------------------------------------------------------


def write_block_figures(blocks: dict[str, BlockAnalysis], out: Path, names: Mapping[str, str] | None = None) -> None:
    """Every block's figures, each drawn once and saved as ``out/block_<id>_<kind>.png|svg``; a panel per
    criterion, titled by its name in ``names`` (criterion id -> label; default: the id)."""
    names = names or {}
    if not blocks:
        return
    # matplotlib is imported when figures are drawn, not with the statistics (a cold start pays for it once)
    from results_analysis import figures
    from results_analysis.paradigm_figures import interval_figure, win_matrix_figure

    for b in blocks.values():
        s, ci = _stem(b), f"{b.ci:.0%}"
        boot = "participant bootstrap" if b.n_boot > 0 else "no interval"
        if b.paradigm == "pairwise":
            res = _of(b, PairwiseResult)
            elo = {names.get(c, c): r.elo for c, r in res.items()}
            figures.save(interval_figure(elo, b.conditions, value="elo",
                                         xlabel="Elo (mean 0)", chance=0.0, fmt="{:+.0f}",
                                         caption=f"Dots: Bradley-Terry strength as Elo (+200 = preferred 76 % of the "
                                         f"time); lines: {ci} {boot} interval."), out, f"{s}_elo")
            wins = {names.get(c, c): r.wins for c, r in res.items()}
            figures.save(win_matrix_figure(wins, b.conditions), out, f"{s}_wins")
        elif b.paradigm == "mismatch":
            res = _of(b, MismatchResult)
            rates = {names.get(c, c): r.rates for c, r in res.items()}
            figures.save(interval_figure(rates, b.conditions, value="rate",
                                         xlabel="matched motion preferred (ties = ½)", chance=0.5, xlim=(0.0, 1.0),
                                         caption=f"Dots: matched-preference rate; lines: {ci} {boot} interval. "
                                         "Dotted line: chance."), out, f"{s}_mismatch")
        else:
            res = _of(b, RatingResult)
            means = {names.get(c, c): r.summary for c, r in res.items()}
            figures.save(interval_figure(means, b.conditions, value="mean",
                                         xlabel="mean rating (0-100)", xlim=(0.0, 100.0), fmt="{:.1f}",
                                         caption=f"Dots: mean rating; lines: {ci} {boot} interval."),
                         out, f"{s}_ratings")


# --- text ---------------------------------------------------------------------------------------------


def _n(v: float, digits: int = 2) -> str:
    from results_analysis.report import _num

    return _num(v, digits)


def _p(p: float, adjusted: bool = False) -> str:
    from results_analysis.report import fmt_p

    return fmt_p(p, adjusted=adjusted)


def _ci(lo: float, hi: float, digits: int = 2) -> str:
    if not (np.isfinite(lo) and np.isfinite(hi)):
        return "no interval"
    return f"{_n(lo, digits)} to {_n(hi, digits)}"


def _pairwise(b: BlockAnalysis, doc: Document, ci: str, names: Mapping[str, str]) -> None:
    doc.p(f"Participants saw two conditions side by side and said which they preferred (clearly, slightly, or no "
          f"preference). Each preference counts as a win whatever its strength; \"no preference\" counts as half a "
          f"win for each condition, as GENEA does. Bradley–Terry strengths were fitted by maximum likelihood "
          f"(Newton's method to convergence) and are reported on the Elo scale, 400·log10(strength), anchored so "
          f"that the conditions' mean Elo is 0: a difference of 200 means the higher one is preferred 76 % of the "
          f"time. Intervals: {n_boot_note(b)}, each resample's wins kept together per participant (a pseudo-count "
          f"of {BOOT_PRIOR:g} wins per pair keeps a resample finite); a condition that never won or never lost has "
          f"no finite strength and is reported as not estimable. Each pair's Elo difference has its interval from "
          f"the same resamples and a two-sided bootstrap p-value (twice the smaller share of resampled differences "
          f"on either side of 0, counted as (1 + count)/(1 + B)), adjusted over the pairs.")
    for crit, r in _of(b, PairwiseResult).items():
        crit = names.get(crit, crit)  # shown by its label from here on
        e = r.elo.sort_values("elo", ascending=False, na_position="last")
        parts = [f"{row.condition} {row.elo:+.0f} ({ci} CI {row.ci_low:+.0f} to {row.ci_high:+.0f})"
                 if np.isfinite(row.elo) and np.isfinite(row.ci_low) else
                 (f"{row.condition} {row.elo:+.0f}" if np.isfinite(row.elo) else
                  f"{row.condition} not estimable ({row.note})") for row in e.itertuples()]
        n = int(r.wins["n"].sum() // 2)
        doc.p(f"**{crit}.** Elo from {n} comparisons: " + ", ".join(parts) + ".")
        show = pd.DataFrame({"condition": r.elo["condition"],
                             "Elo": [f"{v:+.0f}" if np.isfinite(v) else "not estimable" for v in r.elo["elo"]],
                             f"{ci} CI": [_ci(lo, hi, 0) for lo, hi in zip(r.elo["ci_low"], r.elo["ci_high"])],
                             "strength": [_n(v, 3) for v in r.elo["strength"]],
                             "points won": [f"{v:.0%}" if np.isfinite(v) else "n/a" for v in r.elo["score"]],
                             "comparisons": r.elo["n"].astype(int)})
        doc.table(show, f"{b.block} · {crit}: Bradley–Terry Elo (mean 0) with {ci} participant-bootstrap interval.")
        d = r.differences
        if len(d):
            doc.table(pd.DataFrame({
                "pair": [f"{a} vs {b_}" for a, b_ in zip(d["a"], d["b"])],
                "Elo difference": [f"{v:+.0f}" for v in d["difference"]],
                f"{ci} CI": [_ci(lo, hi, 0) for lo, hi in zip(d["ci_low"], d["ci_high"])],
                "implied preference": [f"{v:.0%}" for v in d["p_preferred"]],
                "p_adj": [_p(v, True).split(" ", 1)[1].lstrip("= ") for v in d["p_adjusted"]]}),
                f"{b.block} · {crit}: Elo differences with {ci} participant-bootstrap interval, the share of "
                f"preferences they imply, and bootstrap p-values ({d['adjustment'].iloc[0]}-adjusted over the pairs).")
        w = r.wins
        doc.table(pd.DataFrame({"condition": w["a"], "against": w["b"], "wins": w["wins"], "ties": w["ties"],
                                "losses": w["losses"], "points won": [f"{v:.0%}" if np.isfinite(v) else "n/a"
                                                                      for v in w["score"]]}),
                  f"{b.block} · {crit}: wins, ties and losses of each condition against each other one.")
        if len(r.reasons):
            rs = r.reasons
            doc.table(pd.DataFrame({"reason": rs["reason"], "given": rs["n"],
                                    "of decided trials": [f"{v:.0%}" for v in rs["share"]],
                                    # by position: the columns follow the block's conditions (relabel may have
                                    # renamed them to labels, or not when the study has other conditions too)
                                    **{f"when {c} preferred": rs[col] for c, col in zip(
                                        b.conditions, [x for x in rs.columns if str(x).startswith("preferred_")])}}),
                      f"{b.block} · {crit}: reasons given with a preference, and for which preferred condition.")
    s = _stem(b)
    doc.figure(f"{s}_elo", f"{b.block}: Bradley–Terry Elo with {ci} participant-bootstrap interval.")
    doc.figure(f"{s}_wins", f"{b.block}: share of points of the row condition against the column condition.")


def _mismatch(b: BlockAnalysis, doc: Document, ci: str, names: Mapping[str, str]) -> None:
    adj = next(iter(_of(b, MismatchResult).values())).comparisons["adjustment"].iloc[0] \
        if any(len(r.comparisons) for r in _of(b, MismatchResult).values()) else "Holm"
    doc.p("Each trial showed one condition twice with the trial's speech: once the motion made for that speech "
          "(matched), once a motion made for another clip of the same speaker (mismatched). The score is the "
          "matched-preference rate: matched preferred 1, no preference ½, mismatched preferred 0; chance is 0.5. "
          f"Rates come with {n_boot_note(b)}; the test against 0.5 is a two-sided exact binomial (sign) test on "
          "the trials with a preference (it treats trials as independent; the participant-bootstrap interval is "
          "the evidence that respects repeated measures). Conditions were compared pairwise with Barnard's exact "
          "test (two-sided) on the 2×2 table of matched preferred vs not, ties split half and half (an odd tie "
          f"counted as not preferred), and with a participant bootstrap of the difference of rates; both families "
          f"of p-values were {adj}-adjusted over the pairs.")
    for crit, r in _of(b, MismatchResult).items():
        crit = names.get(crit, crit)  # shown by its label from here on
        t = r.rates
        parts = [f"{row.condition} {row.rate:.0%} ({ci} CI {_ci(100 * row.ci_low, 100 * row.ci_high, 0)} %; "
                 f"{row.matched} matched, {row.equal} equal, {row.mismatched} mismatched preferred; {_p(row.p)})"
                 for row in t.itertuples()]
        text = f"**{crit}.** Matched-preference rates: " + "; ".join(parts) + "."
        comp = r.comparisons
        if len(comp):
            text += " Between conditions: " + "; ".join(
                f"{c.a} vs {c.b}: difference {100 * c.difference:+.0f} points ({ci} CI "
                f"{_ci(100 * c.ci_low, 100 * c.ci_high, 0)}), Barnard {_p(c.p_barnard_adjusted, True)}, "
                f"bootstrap {_p(c.p_bootstrap_adjusted, True)}" for c in comp.itertuples()) + "."
        doc.p(text)
        doc.table(pd.DataFrame({"condition": t["condition"], "trials": t["n"], "participants": t["n_participants"],
                                "matched": t["matched"], "equal": t["equal"], "mismatched": t["mismatched"],
                                "rate": [f"{v:.1%}" for v in t["rate"]],
                                f"{ci} CI": [_ci(100 * lo, 100 * hi, 1) + " %" for lo, hi in zip(t["ci_low"],
                                                                                               t["ci_high"])],
                                "p (vs 0.5)": [_p(v).split(" ", 1)[1].lstrip("= ") for v in t["p"]]}),
                  f"{b.block} · {crit}: matched-preference rate per condition (ties ½) with {ci} participant-"
                  "bootstrap interval and exact binomial test against 0.5.")
        if len(comp):
            doc.table(pd.DataFrame({
                "pair": [f"{a} vs {b_}" for a, b_ in zip(comp["a"], comp["b"])],
                "difference": [f"{100 * v:+.1f}" for v in comp["difference"]],
                f"{ci} CI": [_ci(100 * lo, 100 * hi, 1) for lo, hi in zip(comp["ci_low"], comp["ci_high"])],
                "matched / not (a)": [f"{t_[0][0]} / {t_[1][0]}" for t_ in comp["table"]],
                "matched / not (b)": [f"{t_[0][1]} / {t_[1][1]}" for t_ in comp["table"]],
                "Barnard p_adj": [_p(v, True).split(" ", 1)[1].lstrip("= ") for v in comp["p_barnard_adjusted"]],
                "bootstrap p_adj": [_p(v, True).split(" ", 1)[1].lstrip("= ") for v in comp["p_bootstrap_adjusted"]]}),
                f"{b.block} · {crit}: differences of matched-preference rates (percentage points), "
                f"{adj}-adjusted.")
    doc.figure(f"{_stem(b)}_mismatch", f"{b.block}: matched-preference rate with {ci} participant-bootstrap "
               "interval; dotted line: chance.")


def _rating(b: BlockAnalysis, doc: Document, ci: str, names: Mapping[str, str]) -> None:
    ref = (f" The hidden reference ({b.reference}) is shown with the others but left out of the tests."
           if b.reference is not None else "")
    screen = ""
    if b.screening is not None:
        th, ms = b.screening.attrs.get("threshold", 90), b.screening.attrs.get("max_share", 0.15)
        n_out = int(b.screening["excluded"].sum())
        screen = (f" MUSHRA post-screening: a participant who rated the hidden reference below {th:g} in more than "
                  f"{ms:.0%} of the items (trial × criterion) was excluded from this block; {n_out} of "
                  f"{len(b.screening)} were" + (": " + "; ".join(f"{r.participant} ({r.reason})"
                                                              for r in b.excluded.itertuples()) if n_out else "")
                  + ".")
    doc.p(f"Participants rated every figure of a trial on a 0–100 slider per criterion. Means are over all "
          f"ratings with {n_boot_note(b)}. The conditions were compared with a Friedman test on each "
          f"participant's mean rating per condition (participants as blocks, tie-corrected) and pairwise two-sided "
          f"Wilcoxon signed-rank tests on the same means, {b.adjust.capitalize() if b.adjust != 'bh' else 'BH'}-"
          f"adjusted (exact below {WILCOXON_EXACT_BELOW_N} non-zero differences without ties, else the normal "
          f"approximation with continuity correction).{ref}{screen}")
    for crit, r in _of(b, RatingResult).items():
        crit = names.get(crit, crit)  # shown by its label from here on
        fr = r.friedman.iloc[0]
        s = r.summary
        means = ", ".join(f"{row.condition} {row.mean:.1f} ({ci} CI {_ci(row.ci_low, row.ci_high, 1)})"
                          for row in s.sort_values("mean", ascending=False).itertuples())
        post = "; ".join(f"{p.a} vs {p.b}: V = {p.statistic:g}, r_rb = {_n(p.rank_biserial)}, "
                         f"{_p(p.p_adjusted, True)}" for p in r.posthoc.itertuples())
        n_inc = r.friedman.attrs.get("n_incomplete", 0)
        doc.p(f"**{crit}.** Mean ratings: {means}. Friedman test over {int(fr['n_blocks'])} participants"
              + (f" ({n_inc} who did not rate every condition left out)" if n_inc else "")
              + f": χ²({int(fr['df'])}) = {_n(fr['chi2'])}, {_p(fr['p'])}, Kendall's W = {_n(fr['kendall_w'])}. "
              f"Wilcoxon: {post}.")
        doc.table(pd.DataFrame({"condition": s["condition"], "ratings": s["n"], "participants": s["n_participants"],
                                "mean": [f"{v:.1f}" for v in s["mean"]],
                                f"{ci} CI": [_ci(lo, hi, 1) for lo, hi in zip(s["ci_low"], s["ci_high"])],
                                "median": [f"{v:g}" for v in s["median"]], "SD": [f"{v:.1f}" for v in s["sd"]]}),
                  f"{b.block} · {crit}: ratings per condition with {ci} participant-bootstrap interval.")
    if b.screening is not None and len(b.excluded):
        doc.table(b.excluded, f"{b.block}: participants excluded by the hidden-reference screening.")
    doc.figure(f"{_stem(b)}_ratings", f"{b.block}: mean rating with {ci} participant-bootstrap interval.")


def add_sections(blocks: dict[str, BlockAnalysis], doc: Document, names: Mapping[str, str] | None = None) -> None:
    """One section per block: its method, results text, tables and figures; criteria shown by their name in
    ``names`` (criterion id -> label; default: the id).

    >>> from results_analysis.paradigm_analysis import analyze_blocks
    >>> from results_analysis.simulate import simulate_paradigm
    >>> doc = Document("t")
    >>> add_sections(analyze_blocks(simulate_paradigm("rating", 6, 2, seed=1), n_boot=0), doc)
    >>> doc.to_markdown().count("## Block rating (rating)")
    1
    """
    for b in blocks.values():
        ci = f"{b.ci:.0%}"
        doc.h(1, f"Block {b.block} ({b.paradigm})")
        doc.p(f"{b.n_participants} participants, {b.n_trials} trials, conditions: {', '.join(b.conditions)}.")
        {"pairwise": _pairwise, "mismatch": _mismatch, "rating": _rating}[b.paradigm](b, doc, ci, names or {})
