"""Publication figures of the rank analysis (matplotlib, headless Agg backend).

* :func:`rank_share_figure` — 100% stacked bars of the share of answers at each rank, per criterion.
* :func:`cd_diagram` — Demsar's critical-difference diagram: mean ranks on an axis, bars joining the
  conditions the Nemenyi test cannot separate, the CD drawn to scale.
* :func:`mean_rank_figure` — mean ranks with bootstrap intervals, per criterion.
* :func:`bt_figure` — Bradley-Terry strengths with bootstrap intervals.

Every function returns a Figure; :func:`save` writes it as PNG and SVG.
"""
from __future__ import annotations

from pathlib import Path

import matplotlib
import numpy as np
import pandas as pd
from matplotlib.colors import to_rgb
from matplotlib.figure import Figure

# Figures are built with the object-oriented API (no pyplot), so importing this package never switches
# the matplotlib backend of the caller (a notebook, or the app's own UI) and works headless.

#: Families that have CJK glyphs, tried in order after DejaVu Sans for characters it lacks (Chinese
#: condition labels, criteria and titles); matplotlib >= 3.6 falls back glyph by glyph along the list.
CJK_FAMILIES = ("Noto Sans CJK SC", "Noto Sans CJK JP", "Source Han Sans SC", "WenQuanYi Micro Hei",
                "WenQuanYi Zen Hei", "Microsoft YaHei", "SimHei", "PingFang SC", "Hiragino Sans GB",
                "Heiti SC", "Arial Unicode MS")


def font_families() -> list[str]:
    """DejaVu Sans, then the installed CJK families (only installed ones: others make matplotlib warn)."""
    import logging

    from matplotlib import font_manager

    # A CJK fallback family with no bold face makes matplotlib log "findfont: Failed to find font weight
    # bold" for every bold title, even of an English report; the regular face it then uses is what we want.
    logging.getLogger("matplotlib.font_manager").setLevel(logging.ERROR)

    installed = {e.name for e in font_manager.fontManager.ttflist}
    return ["DejaVu Sans", *(f for f in CJK_FAMILIES if f in installed)]


_STYLE = {
    "font.size": 9, "axes.titlesize": 10, "axes.titleweight": "bold", "axes.labelsize": 9,
    "xtick.labelsize": 8.5, "ytick.labelsize": 8.5, "legend.fontsize": 8.5, "axes.spines.top": False,
    "axes.spines.right": False, "svg.fonttype": "none", "savefig.dpi": 200,
    # laid out and measured at the resolution the PNG is written at: hinted text is about 7 % narrower at
    # 100 dpi, so a layout made there cut captions that then looked as if they fitted
    "figure.dpi": 200, "font.family": font_families(),
}
#: Colour-blind-safe qualitative colours (Okabe-Ito) for conditions.
CONDITION_COLORS = ("#0072B2", "#E69F00", "#009E73", "#CC79A7", "#56B4E9", "#D55E00", "#F0E442", "#000000")


def _figure(size: tuple[float, float]) -> Figure:
    return Figure(figsize=size)


def _caption_y(fig: Figure) -> float:
    """Height (figure fraction) of a caption's baseline: a small margin below it, as the files have no
    ``bbox_inches="tight"`` padding (see :func:`save`)."""
    return 0.06 / fig.get_figheight()


def _fit_width(fig: Figure, *artists) -> None:
    """Widen ``fig`` until every artist spanning it (a centred caption, the legend across the top) fits inside,
    with a small margin. The files are saved without ``bbox_inches="tight"`` (see :func:`save`), so a figure
    sized for one narrow panel (a block that asks one criterion, as the README recommends) would cut them at
    both edges. Measuring text needs no draw of the figure."""
    need = max(a.get_window_extent().width for a in artists) / fig.dpi + 0.25
    if need > fig.get_figwidth():
        fig.set_figwidth(need)


def rank_colors(k: int) -> list[tuple[float, float, float]]:
    """Sequential blues, darkest for rank 1 (best)."""
    cmap = matplotlib.colormaps["Blues"]
    return [cmap(v)[:3] for v in np.linspace(0.9, 0.3, k)]


def condition_color(i: int) -> str:
    return CONDITION_COLORS[i % len(CONDITION_COLORS)]


def save(fig, out_dir: Path, name: str) -> list[Path]:
    """Write ``name.png`` (200 dpi) and ``name.svg`` into ``out_dir``; close the figure.

    Each file is one draw of the figure: every figure lays itself out with ``tight_layout`` when it is built,
    so a plain ``savefig`` keeps its labels inside the canvas (``bbox_inches="tight"`` would draw the whole
    figure a second time just to measure it). ``tight_layout`` leaves a placeholder layout engine behind, for
    which ``savefig`` would also draw the figure once without rendering before each file: the layout is done,
    so the engine is removed.
    """
    out_dir.mkdir(parents=True, exist_ok=True)
    with matplotlib.rc_context({"figure.autolayout": False, "figure.constrained_layout.use": False}):
        fig.set_layout_engine(None)  # with both rc settings off: no engine at all
    paths = [out_dir / f"{name}.png", out_dir / f"{name}.svg"]
    for p in paths:
        fig.savefig(p, facecolor="white", dpi=200)
    return paths


def _order(summary: pd.DataFrame, conditions: list[str] | None) -> list[str]:
    return list(conditions) if conditions is not None else list(summary["condition"])


def rank_share_figure(summaries: dict[str, pd.DataFrame], conditions: list[str] | None = None):
    """One panel per criterion; per condition a 100% bar split into the shares of rank 1..k (a tied answer
    is shared between the places it spans, so every bar is 100%).

    ``summaries``: criterion -> :func:`results_analysis.descriptives.condition_summary` table.
    """
    with matplotlib.rc_context(_STYLE):
        crits = list(summaries)
        first = summaries[crits[0]]
        conds = _order(first, conditions)
        k = len([c for c in first.columns if c.startswith("share_rank_")])
        colors = rank_colors(k)
        fig = _figure((2.3 * len(crits) + 0.6, 0.42 * len(conds) + 1.5))
        axes = fig.subplots(1, len(crits), sharey=True, squeeze=False)
        for ax, crit in zip(axes[0], crits):
            s = summaries[crit].set_index("condition").reindex(conds)
            left = np.zeros(len(conds))
            y = np.arange(len(conds))[::-1]
            for r in range(1, k + 1):
                share = s[f"share_rank_{r}"].to_numpy() * 100.0
                ax.barh(y, share, left=left, color=colors[r - 1], edgecolor="white", linewidth=0.8, height=0.72,
                        label=_rank_label(r, k))
                for yi, l, w in zip(y, left, share):
                    if w >= 14:
                        dark = sum(to_rgb(colors[r - 1])) < 1.6
                        ax.text(l + w / 2, yi, f"{w:.0f}%", ha="center", va="center", fontsize=7.5,
                                color="white" if dark else "#1a1a1a")
                left += share
            ax.set_xlim(0, 100)
            ax.set_xticks([0, 25, 50, 75, 100])
            ax.set_xticklabels(["0", "25", "50", "75", "100"])
            ax.set_title(str(crit))
            ax.tick_params(axis="y", length=0)
            ax.spines["left"].set_visible(False)
            ax.set_yticks(y)
            ax.set_yticklabels(conds)
            n = int(s["n"].iloc[0])
            ax.set_xlabel(f"% of answers (n = {n})")
        handles, labels = axes[0][0].get_legend_handles_labels()
        _fit_width(fig, fig.legend(handles, labels, loc="upper center", ncol=k, frameon=False,
                                   bbox_to_anchor=(0.5, 1.0)))
        fig.tight_layout(rect=(0, 0, 1, 0.9))
        return fig


def _rank_label(r: int, k: int) -> str:
    if r == 1:
        return "ranked 1st (best)"
    if r == k:
        return f"ranked {_ordinal(r)} (worst)"
    return f"ranked {_ordinal(r)}"


def _ordinal(r: int) -> str:
    return f"{r}{'tsnrhtdd'[(r // 10 % 10 != 1) * (r % 10 < 4) * r % 10::4]}"


def cliques(mean_ranks: np.ndarray, cd: float) -> list[tuple[int, int]]:
    """Maximal runs (i, j) of conditions sorted by mean rank whose spread is at most ``cd`` (not separable).

    Indices refer to the sorted order. Single conditions are not cliques.

    >>> cliques(np.array([1.0, 1.2, 2.0, 2.1]), 0.5)
    [(0, 1), (2, 3)]
    """
    r = np.sort(np.asarray(mean_ranks, dtype=float))
    out: list[tuple[int, int]] = []
    for i in range(len(r)):
        j = i
        while j + 1 < len(r) and r[j + 1] - r[i] <= cd + 1e-12:
            j += 1
        if j > i and not any(a <= i and j <= b for a, b in out):
            out.append((i, j))
    return out


def cd_diagram(results: dict[str, tuple[dict[str, float], float]], *, alpha: float = 0.05,
               order: list[str] | None = None, rank_name: str = "Mean rank"):
    """Critical-difference diagrams, one panel per criterion (Demsar 2006, Fig. 1 style).

    ``results``: criterion -> (mean rank per condition, critical difference). Rank 1 (best) is on the
    left; thick black bars join conditions whose mean ranks differ by less than the CD. ``order`` fixes
    the colour of each condition (the same as in the other figures). ``rank_name`` says in the caption which
    mean rank the axis shows (the Friedman test's, of its blocks, can differ from the mean over all answers).
    """
    with matplotlib.rc_context(_STYLE):
        crits = list(results)
        k = len(next(iter(results.values()))[0])
        half = (k + 1) // 2
        panel_h = 0.75 + 0.3 * half
        fig = _figure((6.4, panel_h * len(crits)))
        axes = fig.subplots(len(crits), 1, squeeze=False)
        for ax, crit in zip(axes[:, 0], crits):
            mean_rank, cd = results[crit]
            names = list(mean_rank)
            palette = {n: condition_color(i) for i, n in enumerate(order or names)}
            vals = np.array([mean_rank[n] for n in names])
            by_rank = np.argsort(vals, kind="stable")
            lo, hi = 1.0, float(k)
            ax.set_xlim(lo - 0.9, hi + 0.9)
            ax.set_ylim(-(half + 0.6), 1.6)
            ax.axis("off")
            # Axis with ticks at every whole and half rank.
            ax.plot([lo, hi], [0, 0], color="black", lw=1)
            for t in np.arange(lo, hi + 0.01, 0.5):
                major = float(t).is_integer()
                ax.plot([t, t], [0, 0.12 if major else 0.07], color="black", lw=1)
                if major:
                    ax.text(t, 0.22, f"{int(t)}", ha="center", va="bottom", fontsize=8.5)
            # CD to scale, above the axis at the left.
            ax.plot([lo, lo + cd], [1.05, 1.05], color="#b2182b", lw=1.6)
            for x in (lo, lo + cd):
                ax.plot([x, x], [0.97, 1.13], color="#b2182b", lw=1.2)
            ax.text(lo + cd / 2, 1.2, f"CD = {cd:.2f}", ha="center", va="bottom", fontsize=8, color="#b2182b")
            ax.text(hi + 0.85, 1.2, str(crit), ha="right", va="bottom", fontsize=10, fontweight="bold")
            # Labels: best half to the left, worst half to the right, each on its own line.
            for pos, idx in enumerate(by_rank):
                v = vals[idx]
                if pos < half:
                    y, x_text, ha = -(pos + 0.6), lo - 0.15, "right"
                else:
                    y, x_text, ha = -(k - pos - 1 + 0.6), hi + 0.15, "left"
                color = palette.get(names[idx], "#333333")
                ax.plot([v, v, x_text], [0, y, y], color=color, lw=1.1)
                ax.plot([v], [0], marker="o", ms=3.5, color=color)
                ax.text(x_text + (-0.03 if ha == "right" else 0.03), y, f"{names[idx]}  {v:.2f}" if ha == "left"
                        else f"{v:.2f}  {names[idx]}", ha=ha, va="center", fontsize=8.5)
            # Cliques: bars just below the axis, stacked.
            sorted_vals = vals[by_rank]
            for c_i, (a, b) in enumerate(cliques(sorted_vals, cd)):
                y = -0.22 - 0.16 * c_i
                ax.plot([sorted_vals[a] - 0.05, sorted_vals[b] + 0.05], [y, y], color="black", lw=3,
                        solid_capstyle="round")
        _fit_width(fig, fig.text(0.5, _caption_y(fig), f"{rank_name} (1 = best). Bars join conditions the Nemenyi "
                                 f"test does not separate (α = {alpha:g}).", ha="center", va="bottom", fontsize=7.5,
                                 color="#444444"))
        fig.tight_layout(rect=(0, 0.03, 1, 1))
        return fig


def mean_rank_figure(summaries: dict[str, pd.DataFrame], conditions: list[str] | None = None, *,
                     ci: float = 0.95):
    """Mean rank per condition with its bootstrap interval, one panel per criterion (1 = best, on the left)."""
    with matplotlib.rc_context(_STYLE):
        crits = list(summaries)
        conds = _order(summaries[crits[0]], conditions)
        k = len(conds)
        fig = _figure((2.3 * len(crits) + 0.6, 0.42 * k + 1.3))
        axes = fig.subplots(1, len(crits), sharey=True, squeeze=False)
        y = np.arange(k)[::-1]
        for ax, crit in zip(axes[0], crits):
            s = summaries[crit].set_index("condition").reindex(conds)
            for i, c in enumerate(conds):
                m, lo, hi = s.loc[c, "mean_rank"], s.loc[c, "ci_low"], s.loc[c, "ci_high"]
                color = condition_color(i)
                ax.plot([lo, hi], [y[i], y[i]], color=color, lw=2.2, solid_capstyle="round")
                ax.plot([m], [y[i]], "o", color=color, ms=6, mec="white", mew=0.8)
                ax.text(m, y[i] + 0.22, f"{m:.2f}", ha="center", va="bottom", fontsize=7.5, color="#333333")
            ax.axvline((k + 1) / 2, color="#999999", lw=0.8, ls=":", zorder=0)
            ax.set_xlim(1 - 0.1, k + 0.1)
            ax.set_xticks(np.arange(1, k + 1))
            ax.set_ylim(-0.6, k - 0.3)
            ax.set_yticks(y)
            ax.set_yticklabels(conds)
            ax.tick_params(axis="y", length=0)
            ax.spines["left"].set_visible(False)
            ax.set_title(str(crit))
            ax.set_xlabel("mean rank (1 = best)")
            ax.grid(axis="x", color="#e5e5e5", lw=0.6)
            ax.set_axisbelow(True)
        _fit_width(fig, fig.text(0.5, _caption_y(fig), f"Dots: mean rank; lines: {ci:.0%} percentile bootstrap "
                                 "interval (participants resampled). Dotted line: chance.", ha="center", va="bottom",
                                 fontsize=7.5, color="#444444"))
        fig.tight_layout(rect=(0, 0.05, 1, 1))
        return fig


def bt_figure(tables: dict[str, pd.DataFrame], conditions: list[str] | None = None, *, ci: float = 0.95):
    """Bradley-Terry strengths (sum to 1) with bootstrap intervals, one panel per criterion.

    A strength the data cannot estimate (``estimable`` False, e.g. a condition that never won) gets no bar
    but the words "not estimable" and the table's ``note``, never a bar at 0.
    """
    with matplotlib.rc_context(_STYLE):
        crits = list(tables)
        conds = _order(tables[crits[0]], conditions)
        k = len(conds)
        fig = _figure((2.3 * len(crits) + 0.6, 0.42 * k + 1.3))
        axes = fig.subplots(1, len(crits), sharey=True, squeeze=False)
        y = np.arange(k)[::-1]
        top = max((float(t["ci_high"].max()) if t["ci_high"].notna().any() else float(t["strength"].max())
                   for t in tables.values() if t["strength"].notna().any()), default=1.0)
        flagged = False
        for ax, crit in zip(axes[0], crits):
            t = tables[crit].set_index("condition").reindex(conds)
            for i, c in enumerate(conds):
                color = condition_color(i)
                if "estimable" in t.columns and not bool(t.loc[c, "estimable"]):
                    flagged = True
                    ax.text(0.01 * top, y[i], f"not estimable ({t.loc[c, 'note']})", ha="left", va="center",
                            fontsize=7, color="#b00020", style="italic")
                    continue
                ax.barh(y[i], t.loc[c, "strength"], color=color, height=0.6, alpha=0.85)
                if np.isfinite(t.loc[c, "ci_low"]):
                    ax.plot([t.loc[c, "ci_low"], t.loc[c, "ci_high"]], [y[i], y[i]], color="black", lw=1.2)
            ax.axvline(1.0 / k, color="#999999", lw=0.8, ls=":")
            ax.set_xlim(0, min(1.0, top * 1.1))
            ax.set_ylim(-0.6, k - 0.4)  # every row, also one with no bar (its note would sit on the axis)
            ax.set_yticks(y)
            ax.set_yticklabels(conds)
            ax.tick_params(axis="y", length=0)
            ax.spines["left"].set_visible(False)
            ax.set_title(str(crit))
            ax.set_xlabel("Bradley-Terry strength")
        # the note of a flagged condition goes on a line of its own, which the axes make room for
        _fit_width(fig, fig.text(0.5, _caption_y(fig), f"Bars: strengths (sum to 1); lines: {ci:.0%} bootstrap "
                                 "interval over participants. Dotted line: equal strengths." + (
                                     "\nRed: no finite strength (the condition never won or never lost)."
                                     if flagged else ""), ha="center", va="bottom", fontsize=7.5, color="#444444"))
        fig.tight_layout(rect=(0, 0.05 + (0.13 / fig.get_figheight() if flagged else 0.0), 1, 1))
        return fig
